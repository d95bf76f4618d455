"""``skyfix mosaic SESSION --out DIR``: a georeferenced mosaic of the bottom from a session's video.

Frames are taken about ``--rate-hz`` apart (:func:`groundstation.offline.bottom.subsample_rows`), each with the
camera's pose at its time (:func:`localizer.pose.camera_pose`). A frame's footprint on the floor (its border's
pixels through the refracting flat surface to the floor's depth, :func:`localizer.ray.pixel_to_offset`, no
farther than :data:`MAX_RANGE` slant heights) bounds the cells it can fill; each cell of the north-up grid is
projected back into the frame (:func:`localizer.ray.offset_to_pixel`) and sampled there. A cell keeps the sample
of the frame whose camera was nearest above it (nearest-to-nadir blending: no ghosting of a misplaced frame). The
UUV's pixel (track.csv) and a disc around it (:func:`groundstation.offline.bottom.uuv_radius_px`: its shadow
too) are left out.

The grid is in the UTM zone of the session's first pose (WGS84, metres, EPSG 326xx/327xx); a cell's UTM
coordinates go to the camera's local north/east by each frame's own affine map (UTM's scale and meridian
convergence at the camera, from two points 1 m north and east of it). The video is read once, frame by frame;
only the output grid is held. Written as a Cloud-Optimised GeoTIFF (``mosaic.tif``: RGB and an alpha band,
through rasterio's GDAL), and beside it ``mosaic.json``: the grid, the frames used, and the mosaic's
accuracy (:func:`accuracy_m`).
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from groundstation.offline.bottom import MODES as BOTTOM_MODES
from groundstation.offline.bottom import PoseCorrection, pixels_at, subsample_rows, uuv_radius_px
from groundstation.outputs import output_dir
from groundstation.progress import progress as progress_bar
from groundstation.session.read import PRIMARY_UUV, Session, SessionError, load_session
from localizer.geodesy import ned_to_geodetic
from localizer.pose import CameraPose, camera_pose, take
from localizer.ray import offset_to_pixel, pixel_to_offset

NAME = "mosaic.tif"
SIDECAR = "mosaic.json"
RATE_HZ = 2.0  # frames used per second of video (default)
N_WATER = 1.34
MAX_RANGE = 3.0  # a footprint reaches at most this many times the camera's height above the floor
BORDER_SAMPLES = 16  # pixels per image edge projected to the floor for the footprint
#: pose statuses whose camera is known: the UUV's depth is not needed for the floor
USABLE = ("ok", "no_depth", "stale_depth")


@dataclass
class Grid:
    """A north-up grid: EPSG code, west and north edges (m) and the cell size (m); width and height in cells."""

    epsg: int
    west_m: float
    north_m: float
    gsd_m: float
    width: int
    height: int

    def transform(self):
        from affine import Affine

        return Affine(self.gsd_m, 0.0, self.west_m, 0.0, -self.gsd_m, self.north_m)

    def bounds(self) -> tuple[float, float, float, float]:
        """(west, south, east, north), metres."""
        return (
            self.west_m,
            self.north_m - self.height * self.gsd_m,
            self.west_m + self.width * self.gsd_m,
            self.north_m,
        )


def utm_epsg(lat_deg: float, lon_deg: float) -> int:
    """The WGS84 UTM zone's EPSG code of a point (326xx north, 327xx south)."""
    zone = int((lon_deg + 180.0) // 6.0) % 60 + 1
    return (32600 if lat_deg >= 0 else 32700) + zone


def camera_utm(pose: CameraPose, epsg: int) -> tuple[np.ndarray, np.ndarray]:
    """Each camera's UTM position (N, 2: east, north, m) and the map (N, 2, 2) from its local north/east (m) to
    UTM easting/northing: UTM's scale and meridian convergence at the camera."""
    from rasterio.crs import CRS
    from rasterio.warp import transform

    cam = pose.cam_offset_ned_m
    steps = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])  # the camera, 1 m north, 1 m east
    n = cam[:, None, 0] + steps[None, :, 0]
    e = cam[:, None, 1] + steps[None, :, 1]
    lat, lon, _ = ned_to_geodetic(
        n, e, 0.0, pose.lat_deg[:, None], pose.lon_deg[:, None], pose.alt_amsl_m[:, None]
    )
    x, y = transform(CRS.from_epsg(4326), CRS.from_epsg(epsg), lon.ravel(), lat.ravel())
    xy = np.column_stack([x, y]).reshape(-1, 3, 2)
    jac = np.stack(
        [xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]], axis=-1
    )  # columns: d/dnorth, d/deast
    return xy[:, 0], jac


def footprint_ne_m(camera, pose: CameraPose, k: int, floor_depth_m: float) -> np.ndarray:
    """Frame ``k``'s footprint on the floor: its border's pixels as north/east offsets (M, 2, m) from the camera,
    each no farther than :data:`MAX_RANGE` times the camera's height above the floor."""
    s = np.linspace(0.0, 1.0, BORDER_SAMPLES, endpoint=False)
    w, h = camera.width - 1.0, camera.height - 1.0
    u = np.concatenate([s * w, np.full_like(s, w), (1 - s) * w, np.zeros_like(s)])
    v = np.concatenate([np.zeros_like(s), s * h, np.full_like(s, h), (1 - s) * h])
    off, reaches = pixel_to_offset(
        camera, pose.R_ned_from_cv[k], u, v, pose.height_m[k], floor_depth_m, N_WATER
    )
    far = MAX_RANGE * (pose.height_m[k] + floor_depth_m)
    off = off[reaches & np.all(np.isfinite(off), axis=1)]
    rho = np.linalg.norm(off, axis=1, keepdims=True)
    return off * np.minimum(1.0, far / np.maximum(rho, 1e-9))


def accuracy_m(cal, pose: CameraPose, camera, floor_depth_m: float, floor_sigma_m: float) -> dict:
    """The mosaic's horizontal 1-sigma (m), median over the frames used, at each image centre's floor point: the
    camera's position (``sigma_uav_m``), its tilt and heading (``[uncertainty]`` and the poses' own), its height and
    the floor's depth (the refracted ray's slope times each); and the parts."""
    off, _ = pixel_to_offset(
        camera, pose.R_ned_from_cv, camera.cx, camera.cy, pose.height_m, floor_depth_m, N_WATER
    )
    rho = np.linalg.norm(off, axis=-1)
    tilt = np.hypot(np.radians(cal.sigmas.tilt_deg), pose.sigma_tilt_rad)
    yaw = np.hypot(np.radians(cal.sigmas.yaw_deg), pose.sigma_yaw_rad)
    lever = pose.height_m + floor_depth_m / N_WATER  # d(offset)/d(tilt) at nadir, m/rad
    slope_air = rho / lever  # the ray's horizontal over vertical, approximately
    slope_water = slope_air / N_WATER
    parts = {
        "position_m": pose.sigma_uav_m,
        "tilt_m": lever * (1 + slope_air**2) * tilt,
        "yaw_m": rho * yaw,
        "height_m": slope_air * pose.sigma_height_m,
        "floor_depth_m": slope_water * floor_sigma_m,
    }
    total = np.sqrt(sum(np.square(p) for p in parts.values()))
    return {
        "horizontal_sigma_m": float(np.nanmedian(total)),
        "parts_sigma_m": {k: float(np.nanmedian(p)) for k, p in parts.items()},
    }


def _grid(footprints_utm: list[np.ndarray], epsg: int, gsd_m: float) -> Grid:
    pts = np.concatenate(footprints_utm)
    west, south = np.floor(pts.min(axis=0) / gsd_m) * gsd_m
    east, north = np.ceil(pts.max(axis=0) / gsd_m) * gsd_m
    return Grid(
        epsg,
        float(west),
        float(north),
        gsd_m,
        round((east - west) / gsd_m),
        round((north - south) / gsd_m),
    )


def _paint(
    image, grid: Grid, poly_utm, xy_cam, jac, camera, R, height_m, floor_depth_m, uuv, rgb, best
):
    """Sample ``image`` (BGR) into the cells inside ``poly_utm`` where this frame's camera is nearer above than
    the one that filled them; ``uuv`` = (u, v, radius px) is left out (NaN: nothing)."""
    col = (poly_utm[:, 0] - grid.west_m) / grid.gsd_m - 0.5
    row = (grid.north_m - poly_utm[:, 1]) / grid.gsd_m - 0.5
    c0, c1 = max(0, int(np.floor(col.min()))), min(grid.width, int(np.ceil(col.max())) + 1)
    r0, r1 = max(0, int(np.floor(row.min()))), min(grid.height, int(np.ceil(row.max())) + 1)
    if c1 <= c0 or r1 <= r0:
        return
    inside = np.zeros((r1 - r0, c1 - c0), np.uint8)
    pts = np.round(np.column_stack([col - c0, row - r0]) * 16).astype(np.int32)
    cv2.fillPoly(inside, [pts], 1, shift=4)
    rr, cc = np.mgrid[r0:r1, c0:c1]
    x = grid.west_m + (cc + 0.5) * grid.gsd_m
    y = grid.north_m - (rr + 0.5) * grid.gsd_m
    dxy = np.stack([x - xy_cam[0], y - xy_cam[1]], axis=-1)
    ne = dxy @ np.linalg.inv(jac).T
    u, v = offset_to_pixel(camera, R, ne, height_m, floor_depth_m, N_WATER)
    score = np.linalg.norm(ne, axis=-1)
    ok = (
        (inside == 1)
        & np.isfinite(u)
        & np.isfinite(v)
        & (u >= 0)
        & (u <= camera.width - 1)
        & (v >= 0)
        & (v <= camera.height - 1)
        & (score < best[r0:r1, c0:c1])
    )
    uu, vu, radius = uuv
    if np.isfinite(uu) and np.isfinite(vu):
        ok &= np.hypot(u - uu, v - vu) > radius
    sampled = cv2.remap(
        image,
        np.nan_to_num(u, nan=-1).astype(np.float32),
        np.nan_to_num(v, nan=-1).astype(np.float32),
        cv2.INTER_LINEAR,
    )
    rgb[r0:r1, c0:c1][ok] = sampled[ok][:, ::-1]
    best[r0:r1, c0:c1][ok] = score[ok]


def make_mosaic(
    session: Session,
    out: Path,
    floor_depth_m: float | None,
    floor_sigma_m: float = 0.1,
    rate_hz: float = RATE_HZ,
    gsd_m: float | None = None,
    progress: bool = False,
    correction: PoseCorrection | None = None,
) -> dict:
    """Write ``mosaic.tif`` and ``mosaic.json`` (see the module doc) into ``out``; returns the sidecar's dict.

    ``correction`` (the pose from the bottom, :func:`groundstation.offline.process.bottom_correction`): every
    frame's pose corrected by it, and its floor depth and sigma used where ``floor_depth_m`` is None."""
    cal, cam = session.calibration, session.calibration.camera
    if floor_depth_m is None and correction is not None:
        floor_depth_m = correction.estimate.floor_depth_m
        floor_sigma_m = correction.estimate.sigma_floor_depth_m
    if floor_depth_m is None or not floor_depth_m > 0:
        raise SessionError(
            f"--floor-depth-m {floor_depth_m}: must be a positive depth below the surface, m "
            "(or estimated: --pose-from-bottom auto)"
        )
    if session.video_path is None or session.frames is None:
        raise SessionError(f"{session.path}: no video.* and video_frames.csv to make a mosaic from")
    rows = subsample_rows(session.frames["t"], rate_hz)
    pose = camera_pose(cal, session.telemetry, session.frames["t"][rows])
    if correction is not None:
        pose, cal = correction.apply(session, pose)
    usable = np.isin(pose.status, USABLE) & (pose.height_m > 0)
    if not np.any(usable):
        raise SessionError(
            f"{session.path}: no frame has a camera pose (statuses {set(pose.status)})"
        )
    k0 = int(np.flatnonzero(usable)[0])
    epsg = utm_epsg(pose.lat_deg[k0], pose.lon_deg[k0])
    xy_cam, jac = camera_utm(pose, epsg)
    polys = {
        k: xy_cam[k] + footprint_ne_m(cam, pose, k, floor_depth_m) @ jac[k].T
        for k in np.flatnonzero(usable)
    }
    polys = {k: p for k, p in polys.items() if len(p) >= 3}
    if gsd_m is None:  # the image's own resolution on the floor below the median camera
        gsd_m = float(np.nanmedian(pose.height_m[usable] + floor_depth_m / N_WATER) / cam.fx)
        gsd_m = float(f"{gsd_m:.2g}")
    grid = _grid(list(polys.values()), epsg, gsd_m)
    if session.track is not None:
        uuv_u, uuv_v = pixels_at(
            pose.t_unix, session.track["t"], session.track["u"], session.track["v"]
        )
    else:
        uuv_u = uuv_v = np.full(len(rows), np.nan)
        session.warnings.append(
            f"{session.path}: no track.csv: the UUV is not left out of the mosaic"
        )
    radius = uuv_radius_px(cal, pose)
    rgb = np.zeros((grid.height, grid.width, 3), np.uint8)
    best = np.full((grid.height, grid.width), np.inf, np.float32)
    wanted = {int(session.frames["frame"][r]): k for k, r in enumerate(rows) if k in polys}
    bar = progress_bar(len(wanted), f"{session.path.name}: mosaic", progress)
    try:
        with session.open_video() as video:
            for vf in video.prefetch():
                k = wanted.get(vf.index)
                if k is None:
                    continue
                _paint(
                    vf.image,
                    grid,
                    polys[k],
                    xy_cam[k],
                    jac[k],
                    cam,
                    pose.R_ned_from_cv[k],
                    pose.height_m[k],
                    floor_depth_m,
                    (uuv_u[k], uuv_v[k], radius[k]),
                    rgb,
                    best,
                )
                bar.update()
    finally:
        bar.close()
    write_cog(out / NAME, rgb, np.isfinite(best), grid)
    used = np.array(sorted(polys))
    sidecar = {
        "file": NAME,
        "crs": f"EPSG:{grid.epsg}",
        "bounds_m": dict(zip(("west", "south", "east", "north"), grid.bounds(), strict=True)),
        "gsd_m": grid.gsd_m,
        "size_px": [grid.width, grid.height],
        "frames": len(wanted),
        "rate_hz": rate_hz,
        "blend": "nearest_to_nadir",
        "floor_depth_m": floor_depth_m,
        "floor_depth_sigma_m": floor_sigma_m,
        "pose_source": "bottom" if correction is not None else "telemetry",
        "filled_share": float(np.mean(np.isfinite(best))),
        **accuracy_m(cal, take(pose, used), cam, floor_depth_m, floor_sigma_m),
    }
    (out / SIDECAR).write_text(json.dumps(sidecar, indent=2) + "\n")
    return sidecar


def write_cog(path: Path, rgb: np.ndarray, filled: np.ndarray, grid: Grid) -> None:
    """A Cloud-Optimised GeoTIFF: RGB and an alpha band (255 where a frame filled the cell) on ``grid``."""
    import rasterio
    from rasterio.enums import ColorInterp
    from rasterio.io import MemoryFile
    from rasterio.shutil import copy as copy_raster

    profile = {
        "driver": "GTiff",
        "width": grid.width,
        "height": grid.height,
        "count": 4,
        "dtype": "uint8",
        "crs": rasterio.crs.CRS.from_epsg(grid.epsg),
        "transform": grid.transform(),
        "photometric": "RGB",
    }
    with MemoryFile() as mem, mem.open(**profile) as dst:
        for b in range(3):
            dst.write(rgb[:, :, b], b + 1)
        dst.write(np.where(filled, 255, 0).astype(np.uint8), 4)
        dst.colorinterp = [ColorInterp.red, ColorInterp.green, ColorInterp.blue, ColorInterp.alpha]
        copy_raster(dst, str(path), driver="COG", compress="DEFLATE")


def run(args) -> int:
    out = output_dir(args.out)
    session = load_session(args.session, args.uuv)
    try:
        correction = None
        if args.pose_from_bottom != "off":
            from groundstation.offline.process import bottom_correction, frame_pixels

            pixels = frame_pixels(session, use_track=True)
            correction = bottom_correction(session, pixels, args.pose_from_bottom, not args.quiet)
        found = make_mosaic(
            session,
            out,
            args.floor_depth_m,
            args.floor_depth_sigma_m,
            args.rate_hz,
            args.gsd_m,
            not args.quiet,
            correction,
        )
    finally:
        for w in session.warnings:
            print(f"warning: {w}", file=sys.stderr)
    print(
        f"{found['frames']} frames, {found['size_px'][0]}x{found['size_px'][1]} cells of {found['gsd_m']:g} m "
        f"({found['crs']}), 1-sigma {found['horizontal_sigma_m']:.2f} m -> {out / NAME}"
    )
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help)
    p.add_argument("session", help="session directory (format v1) with its video")
    p.add_argument("--out", required=True, help="output directory for mosaic.tif and mosaic.json")
    p.add_argument(
        "--floor-depth-m",
        type=float,
        default=None,
        metavar="M",
        help="the floor's depth below the water surface, m (default: the pose from the bottom's estimate)",
    )
    p.add_argument(
        "--pose-from-bottom",
        choices=BOTTOM_MODES,
        default="off",
        help="auto: correct every frame's pose by what the static seafloor tells (as skyfix process "
        "--pose-from-bottom auto; UUV pixels from track.csv) and take its floor depth where "
        "--floor-depth-m is not given; off (default)",
    )
    p.add_argument(
        "--floor-depth-sigma-m",
        type=float,
        default=0.1,
        metavar="M",
        help="its 1-sigma, for the mosaic's stated accuracy (default %(default)g)",
    )
    p.add_argument(
        "--rate-hz",
        type=float,
        default=RATE_HZ,
        help="frames used per second of video (default %(default)g)",
    )
    p.add_argument(
        "--gsd-m",
        type=float,
        default=None,
        metavar="M",
        help="the grid's cell size, m (default: the image's resolution on the floor below the camera)",
    )
    p.add_argument(
        "--uuv", default=PRIMARY_UUV, metavar="ID", help="whose track.csv box is left out"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
