"""``skyfix mosaic SESSION --out DIR``: a georeferenced mosaic of the bottom from a session's video.

Frames are taken about ``--rate-hz`` apart (:func:`groundstation.offline.bottom.subsample_rows`), each with the
camera's pose at its time (:func:`localizer.pose.camera_pose`). A frame's footprint on the floor (its border's
pixels through the refracting flat surface to the floor's depth, :func:`localizer.ray.pixel_to_offset`, no
farther than :data:`MAX_RANGE` slant heights) bounds the cells it can fill; each cell of the north-up grid is
projected back into the frame (:func:`localizer.ray.offset_to_pixel`) and sampled there. The cells' colours are
the weighted mean of the frames' samples (:func:`feather_weight`: fading out towards each image's border, so no
seam shows where a frame ends, and favouring frames seen near nadir). The UUV's pixel (the tracker's: the
``u``, ``v`` of a positions.csv, :func:`uuv_pixels`; else track.csv) and a disc around it
(:func:`groundstation.offline.bottom.uuv_radius_px`: its shadow too) are left out.

The grid is in the UTM zone of the session's first pose (WGS84, metres, EPSG 326xx/327xx); a cell's UTM
coordinates go to the camera's local north/east by each frame's own affine map (UTM's scale and meridian
convergence at the camera, from two points 1 m north and east of it). The video is read once, frame by frame;
the blend's sums are kept in tiles (:class:`Accumulator`), at most :data:`MAX_TILES` in memory and the rest on
disk, so the memory does not grow with the recording. Written as a Cloud-Optimised GeoTIFF (``mosaic.tif``: RGB
and an alpha band, through rasterio's GDAL), and beside it ``mosaic.json``: the grid, the frames used, where the
UUV's pixels came from, and the mosaic's accuracy (:func:`accuracy_m`). Then, unless ``--no-tiles``, as
web-Mercator map tiles (:func:`mosaic_tiles`): the folder ``tiles/`` (``Z/X/Y.png``) and ``mosaic.mbtiles``.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from groundstation.map.tiles import GeoTiffTiles, Written, write_tiles
from groundstation.offline.bottom import MODES as BOTTOM_MODES
from groundstation.offline.bottom import PoseCorrection, pixels_at, subsample_rows, uuv_radius_px
from groundstation.offline.progress import progress as progress_bar
from groundstation.outputs import output_dir
from groundstation.session.positions import read_positions_csv
from groundstation.session.read import PRIMARY_UUV, Session, SessionError, load_session
from localizer.geodesy import ned_to_geodetic
from localizer.pose import CameraPose, camera_pose, take
from localizer.ray import offset_to_pixel, pixel_to_offset

NAME = "mosaic.tif"
TILES_DIR = "tiles"  # its map tiles, Z/X/Y.png (XYZ order)
MBTILES = "mosaic.mbtiles"  # the same tiles in an MBTiles file
SIDECAR = "mosaic.json"
RATE_HZ = 2.0  # frames used per second of video (default)
N_WATER = 1.34
MAX_RANGE = 3.0  # a footprint reaches at most this many times the camera's height above the floor
BORDER_SAMPLES = 16  # pixels per image edge projected to the floor for the footprint
# the blend's weight rises from the image's border over this share of its shorter side
FEATHER = 0.1
# cells between the grid points projected exactly into each frame (bilinear between them)
LATTICE = 8
TILE = 256  # the blend's tiles and the GeoTIFF's blocks, cells a side
MAX_TILES = 96  # tiles of the blend held in memory (16 bytes a cell: 100 MB), the rest on disk
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
    # columns: d/dnorth, d/deast
    jac = np.stack([xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]], axis=-1)
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


def feather_weight(camera, u, v, ne_m: np.ndarray, lever_m: float) -> np.ndarray:
    """A sample's weight in the blend: rising from 0 at the image's border to 1 at :data:`FEATHER` of its shorter
    side inside (no seams where frames end), times (lever² / (lever² + ρ²))² for the floor point ρ m (horizontal)
    from below the camera, ``lever_m`` its height plus the floor's refracted depth (frames seen near nadir count most:
    a slightly misplaced oblique frame blurs less)."""
    edge = np.minimum.reduce([u, camera.width - 1 - u, v, camera.height - 1 - v])
    ramp = np.clip(edge / (FEATHER * min(camera.width, camera.height)), 0.0, 1.0)
    rho2 = np.sum(np.square(ne_m), axis=-1)
    return ramp * np.square(lever_m**2 / (lever_m**2 + rho2))


def paint(image, grid: Grid, poly_utm, xy_cam, jac, camera, R, height_m, floor_depth_m, uuv, acc):
    """Add ``image``'s (BGR) samples, weighted (:func:`feather_weight`), into the cells inside ``poly_utm``;
    ``uuv`` = (u, v, radius px): its disc is left out (NaN: nothing)."""
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
    to_ne = np.linalg.inv(jac).T

    def cells_ne(rows, cols):
        x = grid.west_m + (cols + 0.5) * grid.gsd_m
        y = grid.north_m - (rows + 0.5) * grid.gsd_m
        return np.stack([x - xy_cam[0], y - xy_cam[1]], axis=-1) @ to_ne

    ne = cells_ne(rr, cc)
    # the refracted projection on a lattice every LATTICE cells, bilinear between (it is smooth at that scale)
    lr = np.append(np.arange(r0, r1 - 1, LATTICE), r1 - 1)
    lc = np.append(np.arange(c0, c1 - 1, LATTICE), c1 - 1)
    lrr, lcc = np.meshgrid(lr, lc, indexing="ij")
    u_lat, v_lat = offset_to_pixel(camera, R, cells_ne(lrr, lcc), height_m, floor_depth_m, N_WATER)
    at = (np.interp(rr, lr, np.arange(len(lr))), np.interp(cc, lc, np.arange(len(lc))))
    u = map_coordinates(u_lat, at, order=1, mode="nearest")
    v = map_coordinates(v_lat, at, order=1, mode="nearest")
    ok = (
        (inside == 1)
        & np.isfinite(u)
        & np.isfinite(v)
        & (u >= 0)
        & (u <= camera.width - 1)
        & (v >= 0)
        & (v <= camera.height - 1)
    )
    uu, vu, radius = uuv
    if np.isfinite(uu) and np.isfinite(vu):
        ok &= np.hypot(u - uu, v - vu) > radius
    u, v = np.where(ok, u, -1.0), np.where(ok, v, -1.0)
    weight = np.where(ok, feather_weight(camera, u, v, ne, height_m + floor_depth_m / N_WATER), 0.0)
    sampled = cv2.remap(image, u.astype(np.float32), v.astype(np.float32), cv2.INTER_LINEAR)
    block = np.concatenate([sampled[:, :, ::-1] * weight[..., None], weight[..., None]], axis=-1)
    acc.add(r0, c0, block.astype(np.float32))


class Accumulator:
    """The blend's sums over the grid, per cell the weighted R, G, B and the weight (float32), kept in
    :data:`TILE` x :data:`TILE` tiles made where a frame first paints; at most ``max_tiles`` are held in memory, the
    least recently painted written to ``.npy`` files in ``spill_dir`` and read back when painted again. Its memory is
    bounded whatever the recording's length and the grid's extent."""

    def __init__(self, spill_dir: Path, max_tiles: int = MAX_TILES):
        self.spill_dir, self.max_tiles = spill_dir, max_tiles
        self.held: OrderedDict[tuple[int, int], np.ndarray] = OrderedDict()
        self.spilled: set[tuple[int, int]] = set()

    def _path(self, key: tuple[int, int]) -> Path:
        return self.spill_dir / f"tile_{key[0]}_{key[1]}.npy"

    def tile(self, key: tuple[int, int]) -> np.ndarray:
        """Tile ``key`` (tile row, tile column), made or read back, now the most recently used."""
        if key in self.held:
            self.held.move_to_end(key)
            return self.held[key]
        if key in self.spilled:
            self.spilled.discard(key)
            arr = np.load(self._path(key))
        else:
            arr = np.zeros((TILE, TILE, 4), np.float32)
        self.held[key] = arr
        while len(self.held) > self.max_tiles:
            old, old_arr = self.held.popitem(last=False)
            np.save(self._path(old), old_arr)
            self.spilled.add(old)
        return arr

    def add(self, r0: int, c0: int, block: np.ndarray) -> None:
        """Add ``block`` (rows, cols, 4) at grid row ``r0``, column ``c0``."""
        r1, c1 = r0 + block.shape[0], c0 + block.shape[1]
        for tr in range(r0 // TILE, (r1 - 1) // TILE + 1):
            for tc in range(c0 // TILE, (c1 - 1) // TILE + 1):
                a, b = max(r0, tr * TILE), min(r1, (tr + 1) * TILE)
                c, d = max(c0, tc * TILE), min(c1, (tc + 1) * TILE)
                self.tile((tr, tc))[
                    a - tr * TILE : b - tr * TILE, c - tc * TILE : d - tc * TILE
                ] += block[a - r0 : b - r0, c - c0 : d - c0]

    def painted(self) -> list[tuple[int, int]]:
        """The tiles any frame painted, (tile row, tile column)."""
        return sorted(set(self.held) | self.spilled)

    def rgba(self, key: tuple[int, int]) -> np.ndarray:
        """Tile ``key``'s blend (TILE, TILE, 4 uint8): the weighted mean RGB, alpha 255 where a frame painted."""
        arr = self.held[key] if key in self.held else np.load(self._path(key))
        w = arr[:, :, 3:]
        rgb = np.divide(arr[:, :, :3], w, out=np.zeros_like(arr[:, :, :3]), where=w > 0)
        alpha = np.where(w[:, :, 0] > 0, 255, 0)
        return np.dstack([np.clip(np.round(rgb), 0, 255), alpha]).astype(np.uint8)


def uuv_pixels(session: Session, positions: Path | None):
    """The UUV's pixels to leave out, as (t, u, v, where from): ``positions`` (a positions.csv: the tracker's
    ``u``, ``v``, e.g. ``skyfix process``'s output) or the session's own positions.csv (a recorded session's: the
    live tracker's), else its track.csv; None where there is neither."""
    src = positions if positions is not None else session.path / "positions.csv"
    if positions is not None or src.is_file():
        fixes = read_positions_csv(src)
        return fixes.t_unix, fixes.u, fixes.v, str(src)
    if session.track is not None:
        tr = session.track
        return tr["t"], tr["u"], tr["v"], str(session.path / "track.csv")
    return None


def make_mosaic(
    session: Session,
    out: Path,
    floor_depth_m: float | None,
    floor_sigma_m: float = 0.1,
    rate_hz: float = RATE_HZ,
    gsd_m: float | None = None,
    progress: bool = False,
    correction: PoseCorrection | None = None,
    positions: Path | None = None,
    max_tiles: int = MAX_TILES,
) -> dict:
    """Write ``mosaic.tif`` and ``mosaic.json`` (see the module doc) into ``out``; returns the sidecar's dict.

    ``correction`` (the pose from the bottom, :func:`groundstation.offline.process.bottom_correction`): every
    frame's pose corrected by it, and its floor depth and sigma used where ``floor_depth_m`` is None.
    ``positions``: the positions.csv whose pixels are the UUV's (:func:`uuv_pixels`). ``max_tiles``: the
    :class:`Accumulator`'s tiles held in memory."""
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
    found = uuv_pixels(session, positions)
    if found is not None:
        uuv_u, uuv_v = pixels_at(pose.t_unix, *found[:3])
    else:
        uuv_u = uuv_v = np.full(len(rows), np.nan)
        session.warnings.append(
            f"{session.path}: no positions.csv or track.csv: the UUV is not left out of the mosaic"
        )
    radius = uuv_radius_px(cal, pose)
    wanted = {int(session.frames["frame"][r]): k for k, r in enumerate(rows) if k in polys}
    bar = progress_bar(len(wanted), f"{session.path.name}: mosaic", progress)
    with tempfile.TemporaryDirectory(prefix=".mosaic-", dir=out) as spill:
        acc = Accumulator(Path(spill), max_tiles)
        try:
            with session.open_video() as video:
                for vf in video.prefetch():
                    k = wanted.get(vf.index)
                    if k is None:
                        continue
                    paint(
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
                        acc,
                    )
                    bar.update()
        finally:
            bar.close()
        filled = write_cog(out / NAME, acc, grid, Path(spill))
    used = np.array(sorted(polys))
    masked = np.isfinite(uuv_u[used]) & np.isfinite(uuv_v[used])
    sidecar = {
        "file": NAME,
        "crs": f"EPSG:{grid.epsg}",
        "bounds_m": dict(zip(("west", "south", "east", "north"), grid.bounds(), strict=True)),
        "gsd_m": grid.gsd_m,
        "size_px": [grid.width, grid.height],
        "frames": len(wanted),
        "rate_hz": rate_hz,
        "blend": "feathered_mean",
        "floor_depth_m": floor_depth_m,
        "floor_depth_sigma_m": floor_sigma_m,
        "pose_source": "bottom" if correction is not None else "telemetry",
        "uuv_left_out": {
            "pixels_from": None if found is None else found[3],
            "frames": int(masked.sum()),
        },
        "filled_share": filled / (grid.width * grid.height),
        **accuracy_m(cal, take(pose, used), cam, floor_depth_m, floor_sigma_m),
    }
    (out / SIDECAR).write_text(json.dumps(sidecar, indent=2) + "\n")
    return sidecar


def write_cog(path: Path, acc: Accumulator, grid: Grid, scratch: Path) -> int:
    """A Cloud-Optimised GeoTIFF of the blend on ``grid``: RGB and an alpha band (255 where a frame painted the
    cell), written tile by tile to a sparse tiled GeoTIFF in ``scratch`` and copied to a COG with overviews
    (no whole-grid array in memory); returns the cells filled."""
    import rasterio
    from rasterio.enums import ColorInterp
    from rasterio.shutil import copy as copy_raster
    from rasterio.windows import Window

    profile = {
        "driver": "GTiff",
        "width": grid.width,
        "height": grid.height,
        "count": 4,
        "dtype": "uint8",
        "crs": rasterio.crs.CRS.from_epsg(grid.epsg),
        "transform": grid.transform(),
        "photometric": "RGB",
        "tiled": True,
        "blockxsize": TILE,
        "blockysize": TILE,
        "sparse_ok": True,
    }
    filled = 0
    staged = scratch / "staged.tif"
    with rasterio.open(staged, "w", **profile) as dst:
        dst.colorinterp = [ColorInterp.red, ColorInterp.green, ColorInterp.blue, ColorInterp.alpha]
        for tr, tc in acc.painted():
            rgba = acc.rgba((tr, tc))
            h, w = min(TILE, grid.height - tr * TILE), min(TILE, grid.width - tc * TILE)
            rgba = rgba[:h, :w]
            filled += int(np.count_nonzero(rgba[:, :, 3]))
            dst.write(np.moveaxis(rgba, -1, 0), window=Window(tc * TILE, tr * TILE, w, h))
    copy_raster(str(staged), str(path), driver="COG", compress="DEFLATE")
    return filled


def mosaic_of(
    session_path,
    out: Path,
    floor_depth_m: float | None,
    floor_sigma_m: float = 0.1,
    pose_from_bottom: str = "off",
    uuv: str = PRIMARY_UUV,
    positions: Path | None = None,
    progress: bool = False,
    rate_hz: float = RATE_HZ,
    gsd_m: float | None = None,
) -> dict:
    """:func:`make_mosaic` of the session at ``session_path`` (its UUV ``uuv``), its pose corrected from the bottom
    with ``pose_from_bottom`` ``auto`` (the UUV's pixels as :func:`uuv_pixels`); its warnings on stderr."""
    session = load_session(session_path, uuv)
    try:
        correction = None
        if pose_from_bottom != "off":
            from groundstation.offline.process import Pixels, bottom_correction

            found = uuv_pixels(session, positions)
            if found is None:
                raise SessionError(
                    f"{session.path}: no positions.csv or track.csv for the UUV's pixels "
                    "(needed by --pose-from-bottom)"
                )
            pixels = Pixels(*found[:3], np.full(len(found[0]), "ok", dtype=object))
            correction = bottom_correction(session, pixels, pose_from_bottom, progress)
        return make_mosaic(
            session,
            out,
            floor_depth_m,
            floor_sigma_m,
            rate_hz,
            gsd_m,
            progress,
            correction,
            positions,
        )
    finally:
        for w in session.warnings:
            print(f"warning: {w}", file=sys.stderr)


def run(args) -> int:
    out = output_dir(args.out)
    found = mosaic_of(
        args.session,
        out,
        args.floor_depth_m,
        args.floor_depth_sigma_m,
        args.pose_from_bottom,
        args.uuv,
        args.positions,
        not args.quiet,
        args.rate_hz,
        args.gsd_m,
    )
    print(
        f"{found['frames']} frames, {found['size_px'][0]}x{found['size_px'][1]} cells of {found['gsd_m']:g} m "
        f"({found['crs']}), 1-sigma {found['horizontal_sigma_m']:.2f} m -> {out / NAME}"
    )
    if not args.no_tiles:
        done = mosaic_tiles(out)
        print(
            f"{sum(done.tiles.values())} map tiles, zoom {done.minzoom}-{done.maxzoom} -> "
            f"{out / TILES_DIR} and {out / MBTILES}"
        )
    return 0


def mosaic_tiles(out: Path) -> Written:
    """``out``'s ``mosaic.tif`` as web-Mercator map tiles: the folder ``tiles/`` (``Z/X/Y.png``) and
    ``mosaic.mbtiles`` (:func:`groundstation.map.tiles.write_tiles`, zooms from the one where it fits in a tile to its
    own resolution); their ``sigma_m`` is the sidecar's."""
    source = GeoTiffTiles(out / NAME)
    try:
        folder = out / TILES_DIR
        if folder.exists():
            shutil.rmtree(folder)
        return write_tiles(source, folder, out / MBTILES)
    finally:
        source.close()


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help)
    p.add_argument("session", help="session directory (format v1) with its video")
    p.add_argument(
        "--out",
        required=True,
        help="output directory for mosaic.tif, mosaic.json and the map tiles",
    )
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
        "--positions",
        type=Path,
        default=None,
        metavar="FILE",
        help="a positions.csv (skyfix process's output) whose tracked pixels u, v are the UUV's to leave out "
        "(default: the session's positions.csv, else its track.csv)",
    )
    p.add_argument("--uuv", default=PRIMARY_UUV, metavar="ID", help="whose pixels are left out")
    p.add_argument(
        "--no-tiles",
        action="store_true",
        help=f"write no map tiles ({TILES_DIR}/Z/X/Y.png and {MBTILES}; written by default)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
