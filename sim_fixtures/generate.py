"""Write a complete session (format v1) for a scenario: video, telemetry, depth, truth, track.

Ground truth is the UUV's reference point, the centre of its top face (what the
camera sees and the tracker follows), in WGS84 with its depth below the surface;
``depth.jsonl`` reports the depth of that same point. ``track.csv`` holds the
exact distorted pixel of the truth point, one row per frame: where the light from
it crosses the surface (Fermat's principle), projected by OpenCV
(:mod:`sim_fixtures.geometry`, independent of the localizer) or, under waves (``[waves]``), the pixel
whose ray through the wavy surface meets it (:func:`frame_truth`), with ``truth_waves.csv`` beside it: the
waves' own error of that pixel (:func:`wave_error_ne`); where the UUV cannot
be seen, ``u`` and ``v`` are empty: hidden by an occlusion window, outside the image,
less than half of it showing past a second vehicle (``[second_uuv]``),
or too deep in turbid water, its contrast below the sensor noise (see
:meth:`~sim_fixtures.render.Renderer.render`); ``truth.csv`` has every frame. The video is rendered
by ray casting (:mod:`sim_fixtures.render`; a large session by a process per core, each given a copy of the
renderer and each frame's noise offset, so the frames are the same) and encoded by the ``ffmpeg`` CLI
(libx264, yuv420p, raw BGR frames through a pipe; ``[downlink]``: at a drone downlink's bitrate, no B-frames).

Times: the frames' exposure times in ``video_frames.csv``, ``track.csv`` and
``truth.csv`` are on the ground station's clock (true time + ``[clock]
station_offset_s``), as a recording laptop stamps them; ``video_frames.csv``'s are
``[clock] video_time_error_s`` and the error drawn from ``[sensors] video_time_sigma_s`` later than that (a frame
time from a wrong latency, :func:`~sim_fixtures.sensors.video_time_error_s`). ``depth.jsonl`` has one line
per depth measurement, ``{"t": <the UUV's clock when it measured>, "depth_m": <m, positive
down>, "t_recv": <the station's clock when the ground station received it>}``; the UUV's
clock is true time + ``uuv_offset_s``; the depth link takes ``link.depth_delay_s`` plus an
exponential jitter of mean ``link.depth_jitter_s``, arrivals in order.

A second UUV (``[second_uuv] role = "uuv"``) gets the same records in ``uuvs/<id>/`` (the
layout :mod:`groundstation.session.read` reads): ``truth.csv`` and ``track.csv`` of its own
reference point (its track empty where it cannot be seen, less than half of it showing past
the first UUV included), ``depth.jsonl`` by the same sensor and link model (its own random
streams), and ``uuv.toml`` with its ``[tracker]`` box in the first frame it can be seen.

A buoy (``[buoy]``, :mod:`sim_fixtures.buoy`) is rendered with the vehicles; its GPS_RAW_INT, from its own system
id, are merged into ``uav.tlog`` by their receive times, and the session gets its ``reference.toml``,
``reference_track.csv`` and ``buoy_truth.csv``.
"""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
import shutil
import subprocess
import time
from collections import deque
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from groundstation.offline.progress import progress as progress_bar
from groundstation.session.read import UUV_TOML, UUVS_DIR
from localizer.calibration import ConfigError

from .buoy import buoy_ned, gnss_records, hull_m, write_buoy
from .geometry import (
    R_GIMBAL_FROM_CV,
    SimCamera,
    ned_to_geodetic,
    pixel_rays,
    project,
    reach_offset,
    surface_crossing,
)
from .marker import marker_ned, write_reference
from .motion import Motion
from .render import Box, Renderer, View, floor_div, noise_offsets, water_path_ned
from .scenario import DownlinkSpec, Scenario
from .sensors import (
    ahrs_error_rpy,
    camera_error_ned,
    has_slow_errors,
    platform_sigmas,
    position_error_ne_m,
    reported_R_ned_from_gimbal,
    video_time_error_s,
)
from .tlog import Clock, baro_error_m, exponential, gnss_alt_error_m, stream, write_tlog
from .waves import WaveField, wave_field

MARK = "# synthetic session made by skyfix sim"  # first line of session.toml


@dataclass(frozen=True)
class Truth:
    """The true geometry at each frame (arrays over frames)."""

    # exposure time on the ground station's clock (video_frames.csv, track.csv, truth.csv)
    t_unix: np.ndarray
    tau_s: np.ndarray  # seconds since the first frame; true time is start_unix + tau_s
    R_ned_from_cv: np.ndarray  # (N, 3, 3)
    camera_ned: np.ndarray  # (N, 3)
    uuv_ned: np.ndarray  # (N, 3) top-face centre
    uuv_heading: np.ndarray
    visible: np.ndarray  # not occluded
    u: np.ndarray  # exact distorted pixel of the reference point
    v: np.ndarray
    # (N, 3) the second vehicle's top-face centre, if there is one
    second_ned: np.ndarray | None = None
    second_box: Box | None = None  # ... its heading, size and look
    rock: Box | None = None
    # exact distorted pixel of a second UUV's reference point (role = "uuv")
    second_u: np.ndarray | None = None
    second_v: np.ndarray | None = None
    # (N, 2) the waves' own error at the UUV's pixel (wave_error_ne), if waves
    wave_error_ne: np.ndarray | None = None
    second_wave_error_ne: np.ndarray | None = None  # ... at a second UUV's
    # (N, 3) a buoy's marked top's centre ([buoy]), if there is one
    buoy_ned: np.ndarray | None = None
    buoy_box: Box | None = None  # ... its hull
    # a third vehicle ([third_uuv]), as the second's fields
    third_ned: np.ndarray | None = None
    third_box: Box | None = None
    third_u: np.ndarray | None = None
    third_v: np.ndarray | None = None
    third_wave_error_ne: np.ndarray | None = None

    def others(self, i: int) -> tuple[Box, ...]:
        """The look-alikes at frame ``i`` (the second vehicle, the third, the rock), and the buoy last."""
        moving = tuple(
            replace(box, ned=ned[i])
            for box, ned in ((self.second_box, self.second_ned), (self.third_box, self.third_ned))
            if box is not None
        )
        buoy = () if self.buoy_box is None else (replace(self.buoy_box, ned=self.buoy_ned[i]),)
        return moving + (() if self.rock is None else (self.rock,)) + buoy

    def view(self, i: int) -> View:
        return View(
            self.R_ned_from_cv[i],
            self.camera_ned[i],
            self.uuv_ned[i],
            float(self.uuv_heading[i]),
            bool(self.visible[i]),
            float(self.tau_s[i]),
            self.others(i),
        )


def camera_of(sc: Scenario) -> SimCamera:
    """The scenario's camera: fx = fy from the horizontal field of view, principal point at the centre."""
    c = sc.camera
    f = (c.width / 2) / np.tan(np.radians(c.hfov_deg) / 2)
    return SimCamera(
        c.width, c.height, f, f, (c.width - 1) / 2, (c.height - 1) / 2, tuple(c.distortion)
    )


def reference_pixel(camera: SimCamera, R_ned_from_cv, camera_ned, point_ned, n_water: float):
    """Distorted pixel (u, v) of a submerged point: its light's surface crossing, projected by OpenCV.

    ``R_ned_from_cv`` (N, 3, 3), ``camera_ned`` and ``point_ned`` (N, 3), one pose per point.
    """
    crossing = surface_crossing(camera_ned, point_ned, n_water)
    uv = np.array(
        [project(camera, R, c, x) for R, c, x in zip(R_ned_from_cv, camera_ned, crossing)]
    )
    return uv[:, 0], uv[:, 1]


NEWTON_STEP_PX = 0.05  # the finite differences' step of apparent_pixel's Newton iteration ...
NEWTON_TOL_PX = 1e-3  # ... which stops when no pixel moves more than this
NEWTON_ITERATIONS = 30


def _landing(
    camera: SimCamera,
    R_ned_from_cv,
    camera_ned,
    tau_s,
    depth_m,
    waves: WaveField,
    n_water: float,
    u,
    v,
):
    """Where the rays of pixels (u, v) (N, K) of N frames, through the waves, reach ``depth_m`` (N,): (N, K, 2) NE,
    by the renderer's own path for the vehicles' rays (:func:`~sim_fixtures.render.water_path_ned` through the exact
    waves)."""
    n, k = u.shape
    ray = pixel_rays(camera, u, v)
    d = np.einsum("nij,nkj->nki", R_ned_from_cv, ray).reshape(-1, 3)
    p = water_path_ned(d, np.repeat(camera_ned, k, axis=0), n_water, waves.at(np.repeat(tau_s, k)))
    reach = (np.repeat(depth_m, k) - p.down_m) / p.dir_water[:, 2]
    land = p.surface_ne + p.dir_water[:, :2] * reach[:, None]
    land[~p.wet] = np.nan
    return land.reshape(n, k, 2)


def apparent_pixel(
    camera: SimCamera, R_ned_from_cv, camera_ned, tau_s, point_ned, waves: WaveField, n_water: float
):
    """Distorted pixel (u, v) (N,) where submerged points (N, 3) appear through the waves at times ``tau_s`` (N,): the
    pixel whose ray, refracted through the wavy surface, passes through the point. Newton's method on the pixel with
    finite differences, from the flat surface's pixel (:func:`reference_pixel`), to ``NEWTON_TOL_PX``; NaN where it
    does not converge (or the point is outside the lens model)."""
    u, v = reference_pixel(camera, R_ned_from_cv, camera_ned, point_ned, n_water)
    px = np.column_stack([u, v])
    todo = np.flatnonzero(np.isfinite(px).all(axis=1))
    h = NEWTON_STEP_PX
    for _ in range(NEWTON_ITERATIONS):
        if len(todo) == 0:
            break
        uu = px[todo, :1] + np.array([0.0, h, 0.0])
        vv = px[todo, 1:] + np.array([0.0, 0.0, h])
        land = _landing(
            camera,
            R_ned_from_cv[todo],
            camera_ned[todo],
            tau_s[todo],
            point_ned[todo, 2],
            waves,
            n_water,
            uu,
            vv,
        )
        # (N, 2 NE, 2 uv)
        jac = np.stack([land[:, 1] - land[:, 0], land[:, 2] - land[:, 0]], axis=-1) / h
        with np.errstate(invalid="ignore"):
            step = np.linalg.solve(jac, (land[:, 0] - point_ned[todo, :2])[..., None])[..., 0]
        px[todo] -= step
        moved = np.abs(step).max(axis=1)
        px[todo[~np.isfinite(moved)]] = np.nan
        todo = todo[np.isfinite(moved) & (moved > NEWTON_TOL_PX)]
    px[todo] = np.nan  # did not converge
    return px[:, 0], px[:, 1]


def wave_error_ne(
    camera: SimCamera, R_ned_from_cv, camera_ned, point_ned, u, v, n_water: float
) -> np.ndarray:
    """The waves' own error (N, 2, north and east, m) of submerged points seen at pixels (u, v): where the pixel's ray
    reaches the point's depth refracted at a flat surface (:func:`~sim_fixtures.geometry.reach_offset`), minus the
    point. What a localizer with exact telemetry, depth and pixel makes of the scene."""
    d = np.einsum("nij,nj->ni", R_ned_from_cv, pixel_rays(camera, u, v))
    flat = camera_ned[:, :2] + reach_offset(d, -camera_ned[:, 2], point_ned[:, 2], n_water)
    return flat - point_ned[:, :2]


def apparent_radius_m(size_m) -> float:
    """The radius (m) of the disk of a vehicle's top face's area (length × width): the waves its truth pixel is found
    through are averaged over it (:meth:`~sim_fixtures.waves.WaveField.averaged`, see :func:`frame_truth`)."""
    return float(np.sqrt(size_m[0] * size_m[1] / np.pi))


def frame_truth(sc: Scenario, motion: Motion, camera: SimCamera) -> Truth:
    """True state at every frame's exposure time, and the truth point's exact pixel.

    Under waves (``[waves]``) the pixel is where the reference point appears through the waves averaged over the
    top face (a disk of its area, :func:`apparent_radius_m`; :func:`apparent_pixel`): waves longer than the vehicle
    move its image as a whole, shorter ones break it up around there (a point seen through them has several images
    at 1-4 m depth, their displacements averaging out over the vehicle). The rendered silhouette's centroid follows
    that pixel within 0.7-1.1 px RMS per axis at 2-5 m/s (its own break-up included)."""
    n = round(sc.duration_s * sc.fps)
    clock = Clock.of(sc)
    tau = np.arange(n) / sc.fps
    t_unix = clock.station_us(clock.true_us(tau)) / 1e6
    R = motion.R_ned_from_gimbal(tau) @ R_GIMBAL_FROM_CV
    cam = motion.camera_ned(tau)
    uuv = motion.uuv_ned(tau)
    visible = np.ones(n, bool)
    for a, b in sc.occlusions:
        visible &= ~((tau >= a) & (tau < b))
    n_water = sc.site.refractive_index
    waves = wave_field(sc, camera.fx / floor_div(camera))
    if waves is not None:
        waves = waves.averaged(apparent_radius_m(sc.uuv.size_m))

    def pixel(point):  # where a point appears, and the waves' own error there (None without waves)
        if waves is None:
            return (*reference_pixel(camera, R, cam, point, n_water), None)
        pu, pv = apparent_pixel(camera, R, cam, tau, point, waves, n_water)
        return pu, pv, wave_error_ne(camera, R, cam, point, pu, pv, n_water)

    u, v, wave_error = pixel(uuv)
    second = second_ned = rock = second_u = second_v = second_wave_error = None
    if sc.second_uuv.enabled:
        second = Box(motion.second_ned(0.0), motion.second_heading, sc.uuv.size_m, "vehicle")
        second_ned = motion.second_ned(tau)
    if sc.second_uuv.role == "uuv":
        second_u, second_v, second_wave_error = pixel(second_ned)
    third = third_ned = third_u = third_v = third_wave_error = None
    if sc.third_uuv.enabled:
        third_ned = motion.second_ned(tau, "third_uuv")
        third = Box(third_ned[0], motion.third_heading, sc.uuv.size_m, "vehicle")
    if sc.third_uuv.role == "uuv":
        third_u, third_v, third_wave_error = pixel(third_ned)
    if sc.rock.enabled:
        rock = Box(motion.rock_ned, motion.rock_heading, sc.rock.size_m, "rock")
    buoy = buoy_box = None
    if sc.buoy.enabled:
        buoy = buoy_ned(sc, tau)
        buoy_box = Box(buoy[0], 0.0, hull_m(sc), "buoy")
    return Truth(
        t_unix,
        tau,
        R,
        cam,
        uuv,
        motion.uuv_heading(tau),
        visible,
        u,
        v,
        second_ned,
        second,
        rock,
        second_u,
        second_v,
        wave_error,
        second_wave_error,
        buoy,
        buoy_box,
        third_ned,
        third,
        third_u,
        third_v,
        third_wave_error,
    )


def depth_records(
    sc: Scenario, depth_m_at, clock: Clock, streams: tuple[str, str] = ("depth", "depth_link")
) -> list[dict]:
    """The lines of ``depth.jsonl``: a UUV's measurements with its clock's time and the station's arrival time.

    ``depth_m_at(tau_s)`` is its true depth; ``streams`` name the random streams of the sensor and of the link.
    """
    tel = sc.telemetry
    rng = stream(sc, streams[0])
    tau = np.arange(-tel.lead_s, sc.duration_s + 1.0, 1.0 / tel.depth_hz)
    tau = tau + rng.uniform(0.0, 0.2 / tel.depth_hz, len(tau))
    depth = depth_m_at(tau) + rng.normal(0.0, 1.0, len(tau)) * tel.depth_noise_m
    measured = clock.true_us(tau)
    delay = sc.link.depth_delay_s + exponential(
        stream(sc, streams[1]), sc.link.depth_jitter_s, len(tau)
    )
    arrived = np.maximum.accumulate(measured + np.round(delay * 1e6).astype(np.int64))
    return [
        {
            "t": round((m + clock.uuv_offset_us) / 1e6, 6),
            "depth_m": round(float(d), 5),
            "t_recv": round(clock.station_us(a) / 1e6, 6),
        }
        for m, d, a in zip(measured, depth, arrived)
    ]


def _write_csv(path: Path, header, rows) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def _write_depth(path: Path, records: list[dict]) -> None:
    with open(path, "w") as f:
        f.writelines(json.dumps(rec) + "\n" for rec in records)


def _write_truth(path: Path, sc: Scenario, t_unix, ned) -> None:
    """``truth.csv``: a UUV's reference point at each frame time, WGS84 and depth."""
    s = sc.site
    lat, lon, _ = ned_to_geodetic(ned, s.lat_deg, s.lon_deg, s.surface_amsl_m)
    _write_csv(
        path,
        ("t", "lat", "lon", "depth_m"),
        (
            (f"{t:.6f}", f"{a:.10f}", f"{b:.10f}", f"{d:.5f}")
            for t, a, b, d in zip(t_unix, lat, lon, ned[:, 2])
        ),
    )


def _tracked(camera: SimCamera, u, v, in_view) -> np.ndarray:
    """The frames a UUV's pixel (u, v) is written in track.csv: ``in_view`` and in the image."""
    return in_view & camera.contains(np.nan_to_num(u, nan=-1e9), np.nan_to_num(v, nan=-1e9))


def _write_track(path: Path, camera: SimCamera, t_unix, u, v, in_view) -> None:
    """``track.csv``: a UUV's exact pixel at each frame time, empty where it is not ``in_view`` or not in the image."""
    seen = _tracked(camera, u, v, in_view)
    _write_csv(
        path,
        ("t", "u", "v"),
        (
            (f"{t:.6f}", f"{a:.4f}" if ok else "", f"{b:.4f}" if ok else "")
            for t, a, b, ok in zip(t_unix, u, v, seen)
        ),
    )


TRUTH_WAVES_CSV = "truth_waves.csv"


def _write_truth_waves(path: Path, camera: SimCamera, t_unix, u, v, in_view, error_ne) -> None:
    """``truth_waves.csv`` (with ``[waves]``): the waves' own error of a UUV's reference point at each frame time
    (:func:`wave_error_ne`, ``wave_dn_m``, ``wave_de_m``: north and east, m), empty where track.csv is; an earlier
    session's is removed without waves."""
    if error_ne is None:
        path.unlink(missing_ok=True)
        return
    seen = _tracked(camera, u, v, in_view)
    _write_csv(
        path,
        ("t", "wave_dn_m", "wave_de_m"),
        (
            (f"{t:.6f}", f"{dn:.5f}" if ok else "", f"{de:.5f}" if ok else "")
            for t, (dn, de), ok in zip(t_unix, error_ne, seen)
        ),
    )


def _in_view(boxes, otherwise: np.ndarray) -> np.ndarray:
    """The frames a vehicle can be seen in: where it has a rendered box (``boxes``, one per frame, None where it
    cannot be seen), or ``otherwise`` without video (``boxes`` None)."""
    return otherwise if boxes is None else np.array([b is not None for b in boxes])


def _first_box(boxes, t_unix, camera: SimCamera, pad_px: int = 3):
    """``(init_bbox, init_t)``: a vehicle's bounding box in the first frame it is wholly in view in (``boxes``, one
    per frame, None where it cannot be seen; a box cut by the image's edge reaches it), grown by ``pad_px`` and
    still clear of the edge by a pixel, as an operator draws it; None where it never is. A box cut by the edge
    holds part of the vehicle: a tracker started on it fixes off the vehicle's centre (and skyfix refuses it)."""
    for i, b in enumerate(boxes):
        if b is None:
            continue
        x, y, w, h = b
        box = (x - pad_px, y - pad_px, w + 2 * pad_px, h + 2 * pad_px)
        if (
            box[0] >= 1
            and box[1] >= 1
            and box[0] + box[2] <= camera.width - 1
            and box[1] + box[3] <= camera.height - 1
        ):
            return box, float(t_unix[i])
    return None


TRUTH_ERRORS_HEADER = (
    "t",
    "roll_err_deg",
    "pitch_err_deg",
    "yaw_err_deg",
    "cam_err_n_deg",
    "cam_err_e_deg",
    "cam_err_d_deg",
    "north_err_m",
    "east_err_m",
    "height_err_m",
    "gnss_alt_err_m",
)


def write_truth_errors(path: Path, sc: Scenario, motion: Motion, truth: Truth) -> None:
    """``truth_errors.csv``: the telemetry's slow errors (reported − true) at each frame time, the scene's error
    budget (:mod:`sim_fixtures.sensors`; the white noise, new with each message, is not in it).

    ``roll_err_deg``, ``pitch_err_deg``, ``yaw_err_deg``: ATTITUDE's Euler angles; ``cam_err_n_deg``, ``_e_``, ``_d_``:
    the camera's attitude as the telemetry states it (ATTITUDE and the mount's message composed) is the true one
    turned by this rotation vector in NED (about North and East its tilt, about Down its yaw); ``north_err_m``,
    ``east_err_m``: GLOBAL_POSITION_INT's position (the EKF's); ``height_err_m``: its heights ``alt`` and
    ``relative_alt`` (the barometer's); ``gnss_alt_err_m``: GPS_RAW_INT's ``alt``.
    """
    tau = truth.tau_s
    cam = camera_error_ned(
        reported_R_ned_from_gimbal(sc, motion, tau), motion.R_ned_from_gimbal(tau)
    )
    columns = np.column_stack(
        [
            np.degrees(ahrs_error_rpy(sc, tau)),
            np.degrees(cam),
            position_error_ne_m(sc, tau),
            baro_error_m(sc, tau),
            gnss_alt_error_m(sc, tau),
        ]
    )
    _write_csv(
        path,
        TRUTH_ERRORS_HEADER,
        ([f"{t:.6f}", *(f"{x:.6f}" for x in row)] for t, row in zip(truth.t_unix, columns)),
    )


def _session_toml(sc: Scenario, camera: SimCamera, init_bbox, init_t: float | None) -> str:
    s, m = sc.site, sc.mount

    def vec(x):
        return "[" + ", ".join(repr(float(a)) for a in x) + "]"

    water = (
        f"takeoff_height_above_surface_m = {s.takeoff_height_above_surface_m!r}"
        if s.water_reference == "takeoff"
        else f"surface_amsl_m = {s.surface_amsl_m!r}"
    )
    return (
        f"""{MARK} from scenario "{sc.name}" (seed {sc.seed})
version = 1

[camera]
width = {camera.width}
height = {camera.height}
fx = {float(camera.fx)!r}
fy = {float(camera.fy)!r}
cx = {float(camera.cx)!r}
cy = {float(camera.cy)!r}
distortion = {vec(camera.distortion)}

[mount]
attitude_source = "{m.attitude_source}"
fixed_rpy_deg = {vec(m.fixed_rpy_deg)}
camera_offset_m = {vec(m.camera_offset_m)}

[water]
{water}
refractive_index = {s.refractive_index!r}

[uuv]  # the simulated vehicle's box
length_m = {float(sc.uuv.size_m[0])!r}
width_m = {float(sc.uuv.size_m[1])!r}
height_m = {float(sc.uuv.size_m[2])!r}
"""
        + _tracker_toml(init_bbox, init_t)
        + _uncertainty_toml(sc)
    )


def _uuv_toml(sc: Scenario, uuv_id: str, init) -> str:
    """A second UUV's ``uuv.toml``: its ``[tracker]`` table (none where it is never seen, or without video)."""
    head = f'{MARK} from scenario "{sc.name}": the UUV "{uuv_id}", its records beside this file\n'
    return head + (_tracker_toml(*init) if init is not None else "")


def _tracker_toml(init_bbox, init_t) -> str:
    if init_bbox is None:
        return ""
    return f"""
[tracker]
init_bbox = [{", ".join(str(int(x)) for x in init_bbox)}]
init_t = {init_t!r}
"""


def _uncertainty_toml(sc: Scenario) -> str:
    """An ``[uncertainty]`` table stating the scenario's telemetry noise, when it has any, with the sigmas a platform
    with its ``[sensors]`` would state (:func:`~sim_fixtures.sensors.platform_sigmas`), the wind over its waves, and
    how well the water's altitude is known (``site.surface_amsl_sigma_m``), when given."""
    t, known = sc.telemetry, sc.site.surface_amsl_sigma_m
    noise = bool(t.attitude_noise_deg or t.height_noise_m or t.depth_noise_m)
    keys = (
        {
            "tilt_deg": t.attitude_noise_deg,
            "yaw_deg": t.attitude_noise_deg,
            "height_m": t.height_noise_m,
            "depth_m": t.depth_noise_m,
        }
        if noise
        else {}
    )
    platform = platform_sigmas(sc)
    for k, sigma in platform.items():
        keys[k] = float(np.hypot(keys.get(k, 0.0), sigma))
    if sc.waves.wind_mps:
        platform["wind_mps"] = keys["wind_mps"] = float(sc.waves.wind_mps)
    if not keys and known is None:
        return ""
    why = ["the simulated telemetry noise (1-sigma per sample)"] if noise else []
    why += (
        ["the drone's sensors as its platform would state them, the wind as its operator"]
        if platform
        else []
    )
    text = "\n[uncertainty]" + (f"  # {'; '.join(why)}\n" if why else "\n")
    text += "".join(
        f"{k} = {round(v, 6)!r}\n" if k in platform else f"{k} = {v!r}\n" for k, v in keys.items()
    )
    if known is not None:
        text += f"surface_amsl_m = {known!r}  # how well the water's altitude is known\n"
    return text


def rate_control(crf: int, downlink: DownlinkSpec | None, fps: float) -> list[str]:
    """x264's rate control and GOP options: quality ``crf`` with a keyframe a second (``downlink`` None or without a
    bitrate, and then ``keyframe_s`` sets the GOP); or as a drone's downlink, ``bitrate_mbps`` constant (``-b:v`` =
    ``-maxrate``, ``-bufsize`` ``buffer_s`` of it) without B-frames (``-bf 0``: each frame sent as it is made), on one
    thread: x264's rate control with a buffer on several frame threads reads the sizes of frames still being encoded,
    so the same frames came out differently from one render to the next (every decoded frame from the 9th on, in
    tests/test_sim_waves.py's clip): a scenario renders to the same video every time only on one thread."""
    gop = str(max(1, round((1.0 if downlink is None else downlink.keyframe_s) * fps)))
    if downlink is None or downlink.bitrate_mbps is None:
        return ["-crf", str(crf), "-g", gop]
    rate = round(downlink.bitrate_mbps * 1e6)
    return [
        "-b:v",
        str(rate),
        "-maxrate",
        str(rate),
        "-bufsize",
        str(round(rate * downlink.buffer_s)),
        "-bf",
        "0",
        "-g",
        gop,
        "-threads",
        "1",
    ]


class Encoder:
    """``ffmpeg`` reading raw BGR frames on stdin, writing H.264 (libx264, yuv420p, a keyframe a second) MP4;
    ``downlink``: a scenario's ``[downlink]`` (:func:`rate_control`)."""

    def __init__(
        self,
        path: Path,
        width: int,
        height: int,
        fps: float,
        crf: int,
        downlink: DownlinkSpec | None = None,
    ):
        if shutil.which("ffmpeg") is None:
            raise RuntimeError(
                "ffmpeg not found on PATH; install it (apt install ffmpeg) to render video"
            )
        cmd = [
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "bgr24",
            "-s",
            f"{width}x{height}",
            "-r",
            f"{fps:g}",
            "-i",
            "-",
            "-an",
            "-c:v",
            "libx264",
            "-preset",
            "veryfast",
            # a keyframe every second by default, as field cameras send: a
            *rate_control(crf, downlink, fps),
            # live decoder that joins late starts within a second
            "-pix_fmt",
            "yuv420p",
            "-movflags",
            "+faststart",
            str(path),
        ]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE)

    def write(self, frame_bgr: np.ndarray) -> None:
        self.proc.stdin.write(frame_bgr.tobytes())

    def close(self) -> None:
        self.proc.stdin.close()
        if self.proc.wait() != 0:
            raise RuntimeError(f"ffmpeg exited with status {self.proc.returncode}")


#: Sessions of at least this many pixels (frames × width × height: 2 s of 720p) are rendered by several processes.
PARALLEL_PIXELS = 60 * 1280 * 720
MAX_WORKERS = 4


def render_workers(camera: SimCamera, n_frames: int) -> int:
    """How many processes render a session: one per core this process may use (at most :data:`MAX_WORKERS`), or
    none beside this one for a small session (a worker's start, about a second, would cost more than it saves)."""
    if n_frames * camera.width * camera.height < PARALLEL_PIXELS:
        return 1
    return max(
        1, min(MAX_WORKERS, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)
    )


_worker_renderer: Renderer | None = None  # a rendering process's renderer


def _start_worker(renderer: Renderer) -> None:
    global _worker_renderer
    _worker_renderer = renderer


def _render_apart(view: View, noise_at: tuple[int, int]):
    return _worker_renderer.render_seen(view, noise_at)


BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def _one_blas_thread():
    """Processes started meanwhile use one BLAS thread each: the rendering processes already fill the cores (the
    waves' matrix products, each on two threads beside them, ran 3-10 times slower on a busy 2-core machine)."""
    saved = {k: os.environ.get(k) for k in BLAS_THREADS}
    os.environ.update(dict.fromkeys(BLAS_THREADS, "1"))
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _frames(renderer: Renderer, sc: Scenario, truth: Truth, workers: int) -> Iterator[tuple]:
    """``render_seen``'s (image, boxes) of every frame in order: rendered here, or by ``workers`` processes (each
    given a copy of the renderer and each frame's noise offset: the same frames), at most two a worker ahead."""
    n = len(truth.t_unix)
    if workers <= 1:
        for i in range(n):
            yield renderer.render_seen(truth.view(i))
        return
    offsets = noise_offsets(sc, n)
    with (
        _one_blas_thread(),
        ProcessPoolExecutor(
            workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_start_worker,
            initargs=(renderer,),
        ) as pool,
    ):
        ahead: deque = deque()
        for i in range(n):
            ahead.append(pool.submit(_render_apart, truth.view(i), offsets[i]))
            if len(ahead) >= 2 * workers:
                yield ahead.popleft().result()
        while ahead:
            yield ahead.popleft().result()


def _render(
    sc: Scenario, camera: SimCamera, truth: Truth, path: Path, progress: bool = False
) -> list[tuple]:
    """Render (in :func:`render_workers` processes) and encode every frame; returns per frame the bounding box of the
    UUV and of each look-alike where it can be seen, else None (see :meth:`~sim_fixtures.render.Renderer.render_seen`)."""
    renderer = Renderer(sc, camera)
    encoder = Encoder(path, camera.width, camera.height, sc.fps, sc.render.crf, sc.downlink)
    n = len(truth.t_unix)
    seen = []
    bar = progress_bar(n, f"{sc.name}: rendering", progress)
    try:
        for img, boxes in _frames(renderer, sc, truth, render_workers(camera, n)):
            seen.append(boxes)
            encoder.write(img)
            bar.update()
    finally:
        bar.close()
        encoder.close()
    return seen


def _write_second_uuv(
    out: Path,
    sc: Scenario,
    camera: SimCamera,
    truth: Truth,
    motion: Motion,
    clock: Clock,
    boxes: list | None,
    which: str = "second",
) -> None:
    """A second UUV's records in ``uuvs/<id>/``; ``boxes`` its bounding box per frame where it can be seen (None
    without video: then it counts as seen wherever it is in the image, and has no first box). ``which`` "third":
    the third UUV's (``[third_uuv]``)."""
    key = f"{which}_uuv"
    ned, u, v = (getattr(truth, f"{which}_{k}") for k in ("ned", "u", "v"))
    folder = out / UUVS_DIR / getattr(sc, key).id
    folder.mkdir(parents=True, exist_ok=True)
    _write_depth(
        folder / "depth.jsonl",
        depth_records(
            sc,
            lambda tau: motion.second_ned(tau, key)[..., 2],
            clock,
            (f"{which}_depth", f"{which}_link"),
        ),
    )
    _write_truth(folder / "truth.csv", sc, truth.t_unix, ned)
    in_view = _in_view(boxes, np.ones(len(truth.t_unix), bool))
    _write_track(folder / "track.csv", camera, truth.t_unix, u, v, in_view)
    _write_truth_waves(
        folder / TRUTH_WAVES_CSV,
        camera,
        truth.t_unix,
        u,
        v,
        in_view,
        getattr(truth, f"{which}_wave_error_ne"),
    )
    init = None if boxes is None else _first_box(boxes, truth.t_unix, camera)
    (folder / UUV_TOML).write_text(_uuv_toml(sc, getattr(sc, key).id, init))


@dataclass(frozen=True)
class Report:
    session: Path
    frames: int
    render_s: float  # rendering + encoding time
    total_s: float
    messages: dict


def generate(
    sc: Scenario,
    out_dir: str | Path,
    scenario_text: str | None = None,
    video: bool = True,
    progress: bool = False,
) -> Report:
    """Write the session for ``sc`` into ``out_dir``.

    The directory is created; a session generated earlier is overwritten, any other
    session (a real recording) is refused with :class:`ConfigError`. ``video=False``
    renders nothing (fast: telemetry, depth, truth and track.csv only): no video.mp4
    and no ``[tracker]`` table, and track.csv counts the UUV as seen wherever it is in
    the image and not occluded (the renderer's contrast test needs the rendering).
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    existing = out / "session.toml"
    if existing.is_file() and not existing.read_text(errors="replace").startswith(MARK):
        raise ConfigError(
            str(out),
            "--out",
            str(out),
            "holds a session not made by skyfix sim; refusing to overwrite it",
        )
    if (
        existing.is_file() and (out / UUVS_DIR).is_dir()
    ):  # an earlier generated session's other UUVs
        shutil.rmtree(out / UUVS_DIR)
    out.mkdir(parents=True, exist_ok=True)
    camera = camera_of(sc)
    motion = Motion(sc)
    truth = frame_truth(sc, motion, camera)
    clock = Clock.of(sc)

    buoy_heard = gnss_records(sc, clock, -sc.telemetry.lead_s / 2)
    messages = write_tlog(out / "uav.tlog", sc, motion, clock, buoy_heard)
    _write_depth(out / "depth.jsonl", depth_records(sc, motion.uuv_depth_m, clock))
    _write_truth(out / "truth.csv", sc, truth.t_unix, truth.uuv_ned)
    marker_uv = (None, None)
    if sc.marker.enabled:
        point = np.broadcast_to(marker_ned(sc), truth.camera_ned.shape)
        marker_uv = reference_pixel(
            camera, truth.R_ned_from_cv, truth.camera_ned, point, sc.site.refractive_index
        )
    write_reference(out, sc, truth.t_unix, *marker_uv, camera.width, camera.height)
    buoy_uv = (None, None)
    if sc.buoy.enabled:
        buoy_uv = reference_pixel(
            camera, truth.R_ned_from_cv, truth.camera_ned, truth.buoy_ned, sc.site.refractive_index
        )
    write_buoy(out, sc, truth.t_unix, truth.buoy_ned, *buoy_uv, camera.width, camera.height)
    if has_slow_errors(sc):
        write_truth_errors(out / "truth_errors.csv", sc, motion, truth)
    else:
        (out / "truth_errors.csv").unlink(missing_ok=True)  # an earlier generated session's
    stamped = truth.t_unix + video_time_error_s(sc)
    _write_csv(
        out / "video_frames.csv", ("frame", "t"), ((i, f"{t:.6f}") for i, t in enumerate(stamped))
    )

    t1 = time.perf_counter()
    seen = None  # per frame, the boxes of the UUV and the look-alikes where they can be seen (with video)
    if video:
        seen = _render(sc, camera, truth, out / "video.mp4", progress)
    else:
        for old in out.glob("video.*"):
            old.unlink()
    render_s = time.perf_counter() - t1
    uuv_boxes = None if seen is None else [boxes[0] for boxes in seen]
    in_view = _in_view(uuv_boxes, truth.visible)
    _write_track(out / "track.csv", camera, truth.t_unix, truth.u, truth.v, in_view)
    _write_truth_waves(
        out / TRUTH_WAVES_CSV, camera, truth.t_unix, truth.u, truth.v, in_view, truth.wave_error_ne
    )
    init = None if seen is None else _first_box(uuv_boxes, truth.t_unix, camera)
    if seen is not None and init is None:
        raise ValueError(
            f"scenario {sc.name}: the UUV is never wholly in view, so there is no init_bbox"
        )
    (out / "session.toml").write_text(_session_toml(sc, camera, *(init or (None, None))))
    if sc.second_uuv.role == "uuv":
        _write_second_uuv(
            out, sc, camera, truth, motion, clock, None if seen is None else [b[1] for b in seen]
        )
    if sc.third_uuv.role == "uuv":  # its box after the second vehicle's (Truth.others)
        boxes = None if seen is None else [b[2] for b in seen]
        _write_second_uuv(out, sc, camera, truth, motion, clock, boxes, "third")
    if scenario_text is not None:
        (out / "scenario.toml").write_text(scenario_text)
    return Report(out, len(truth.t_unix), render_s, time.perf_counter() - t0, messages)
