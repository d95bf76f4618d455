"""Where the telemetry says the UUV should appear: pixel, apparent size and uncertainty.

The UUV's reference point is the centre of its top face (its depth is the depth
reported). A box drawn around the whole visible vehicle is centred elsewhere
when the camera looks obliquely, because the side facing the camera shows below
the top face: :func:`top_face_pixel` corrects for it.

A UUV last located at (lat, lon) is projected into a frame through that frame's
:class:`~localizer.pose.CameraPose` with refraction (:func:`localizer.ray.offset_to_pixel`),
which accounts for everything the UAV and its gimbal did since. Its apparent size
follows from the same projection: the image scale ``px_per_m`` (pixels per metre
of horizontal offset at the UUV's depth, the geometric mean of both directions)
times the vehicle's footprint. Batched over the pose's frames.
"""

from __future__ import annotations

import math

import numpy as np

from ..calibration import Calibration
from ..geodesy import geodetic_to_ned
from ..pose import CameraPose
from ..ray import offset_to_pixel, pixel_to_offset
from . import Prediction

VEHICLE_FOOTPRINT_M = (0.46, 0.34)  # BlueROV2-sized: length, beam (metres)
VEHICLE_HEIGHT_M = 0.25  # from the top face down to the bottom
UUV_SPEED_MPS = 1.0  # how fast the UUV's own position estimate's 1-sigma grows with its age (m/s)
UUV_TOP_SPEED_MPS = 1.5  # a BlueROV2's top speed (``skyfix run --uuv-max-speed-mps``'s default)
#: Its horizontal acceleration from rest (m/s²): the thrust holding its top speed, 47 N by the surge damping Wu
#: (2018) identified, over its mass with the added mass, 17 kg (the safety gates' bound, localizer.fix_gate).
UUV_ACCEL_MPS2 = 3.0
#: How fast the UUV may turn (deg/s): ArduSub's yaw rate at full stick and full joystick gain, ACRO_YAW_P (4.5) × 45°.
UUV_YAW_RATE_DPS = 200.0
# ... plus this: the camera's own turning, and the heading followed lagging a turn
TURN_MARGIN_DEG = 10.0
BASE_SIGMA_M = 0.08  # the prediction's 1-sigma from the telemetry itself (attitude, timing)
_STEP_M = 0.05  # finite-difference step for the image scale
WINDOW_SIGMAS = 3.0  # the search window the matchers use: the prediction ± this many sigmas


def project_uuv(cal: Calibration, pose: CameraPose, lat_deg, lon_deg, depth_m=None):
    """``(u, v, px_per_m)`` arrays: where a UUV at (lat, lon, depth) appears in each of the pose's frames.

    ``depth_m`` defaults to the pose's depth (the UUV's measured depth at each
    frame). NaN where the pose has no ``ok`` status or the point is not in front of the camera.
    """
    depth = (
        pose.depth_m
        if depth_m is None
        else np.broadcast_to(np.asarray(depth_m, float), pose.t_unix.shape)
    )
    n, e, _ = geodetic_to_ned(lat_deg, lon_deg, 0.0, pose.lat_deg, pose.lon_deg, 0.0)
    ne = np.stack([n - pose.cam_offset_ned_m[:, 0], e - pose.cam_offset_ned_m[:, 1]], axis=-1)
    probes = ne[:, None, :] + np.array([[0.0, 0.0], [_STEP_M, 0.0], [0.0, _STEP_M]])  # (N, 3, 2)
    n_water = cal.water.refractive_index
    u, v = offset_to_pixel(
        cal.camera,
        pose.R_ned_from_cv[:, None],
        probes,
        pose.height_m[:, None],
        depth[:, None],
        n_water,
    )
    du_n, dv_n = u[:, 1] - u[:, 0], v[:, 1] - v[:, 0]
    du_e, dv_e = u[:, 2] - u[:, 0], v[:, 2] - v[:, 0]
    px_per_m = np.sqrt(np.abs(du_n * dv_e - dv_n * du_e)) / _STEP_M
    bad = pose.status != "ok"
    return (
        np.where(bad, np.nan, u[:, 0]),
        np.where(bad, np.nan, v[:, 0]),
        np.where(bad, np.nan, px_per_m),
    )


def top_face_pixel(
    cal: Calibration, pose: CameraPose, box_u, box_v, height_m: float = VEHICLE_HEIGHT_M
):
    """The pixel of the top face's centre, given the centre (box_u, box_v) of a box around the whole vehicle.

    The vehicle's outline spans its top face (at the reported depth) and its
    bottom face (``height_m`` deeper); a box around it is centred halfway between
    where the two faces' centres appear, so the top face's centre lies half that
    displacement back. Batched over the pose's frames; unchanged where the pose is not ``ok``.
    """
    box_u = np.asarray(box_u, dtype=float)
    box_v = np.asarray(box_v, dtype=float)
    n_water = cal.water.refractive_index
    off, _ = pixel_to_offset(
        cal.camera, pose.R_ned_from_cv, box_u, box_v, pose.height_m, pose.depth_m, n_water
    )
    probes = np.stack([off, off], axis=-2)  # (N, 2, 2): the same horizontal offset at both depths
    depths = np.stack([pose.depth_m, pose.depth_m + height_m], axis=-1)
    u, v = offset_to_pixel(
        cal.camera, pose.R_ned_from_cv[:, None], probes, pose.height_m[:, None], depths, n_water
    )
    du, dv = (u[:, 1] - u[:, 0]) / 2.0, (v[:, 1] - v[:, 0]) / 2.0
    good = (pose.status == "ok") & np.isfinite(du) & np.isfinite(dv)
    return np.where(good, box_u - du, box_u), np.where(good, box_v - dv, box_v)


def prediction_at(
    u: float,
    v: float,
    px_per_m: float,
    sigma_m: float,
    shift_px=(0.0, 0.0),
    turn_deg: float = math.nan,
) -> Prediction | None:
    """A :class:`Prediction` from one frame's projection (see :func:`project_uuv`); None if it is NaN.

    ``sigma_m``: how far (1-sigma, metres) the UUV may have moved since the
    position that was projected; ``shift_px``: a pixel correction added to the
    projection, e.g. the residual between the last tracked pixel and the
    projection at that frame; ``turn_deg``: how far its heading may have turned (NaN: any).
    """
    if not (math.isfinite(u) and math.isfinite(v) and px_per_m > 0):
        return None
    length_m, beam_m = VEHICLE_FOOTPRINT_M
    return Prediction(
        u=float(u + shift_px[0]),
        v=float(v + shift_px[1]),
        width_px=float(length_m * px_per_m),
        height_px=float(beam_m * px_per_m),
        sigma_px=float(sigma_m * px_per_m),
        px_per_m=float(px_per_m),
        turn_deg=turn_deg,
    )


def window(
    prediction: Prediction | None, sigmas: float = WINDOW_SIGMAS
) -> tuple[float, float, float, float] | None:
    """``(x, y, w, h)`` pixels where the predicted vehicle may lie: its centre ± ``sigmas`` of the prediction's
    uncertainty, widened by half the vehicle's diagonal (None without a prediction, or one of unknown uncertainty)."""
    if prediction is None or not math.isfinite(prediction.sigma_px):
        return None
    half = (
        sigmas * prediction.sigma_px + math.hypot(prediction.width_px, prediction.height_px) / 2.0
    )
    return (prediction.u - half, prediction.v - half, 2.0 * half, 2.0 * half)


def reach_m(dt_s: float, speed_mps: float = math.nan) -> float:
    """How far (m) from where it was seen ``dt_s`` ago the UUV can be: moving on at ``speed_mps`` (NaN: unknown,
    its top speed) and speeding up at most at :data:`UUV_ACCEL_MPS2`, never beyond :data:`UUV_TOP_SPEED_MPS`; plus
    the telemetry's own error, :data:`WINDOW_SIGMAS` × :data:`BASE_SIGMA_M`."""
    dt = abs(dt_s)
    v = min(speed_mps, UUV_TOP_SPEED_MPS) if speed_mps >= 0 else UUV_TOP_SPEED_MPS
    return (
        min(v * dt + 0.5 * UUV_ACCEL_MPS2 * dt * dt, UUV_TOP_SPEED_MPS * dt)
        + WINDOW_SIGMAS * BASE_SIGMA_M
    )


def follow(
    projected_now, projected_then, pixel_then, dt_s: float, speed_mps: float = math.nan
) -> Prediction | None:
    """Prediction for a frame: the last tracked pixel moved by what the camera did since.

    ``projected_now`` ``(u, v, px_per_m)`` and ``projected_then`` ``(u, v, ...)``: the
    UUV's last located position projected (:func:`project_uuv`) into this frame and
    into the frame it was tracked in; ``pixel_then``: the pixel tracked there. The
    residual between that pixel and its projection is carried over; the window
    (:data:`WINDOW_SIGMAS` sigmas) is as wide as the UUV, last seen moving at ``speed_mps``
    (NaN: unknown), can have gone in the ``dt_s`` seconds since (:func:`reach_m`), and its
    heading may have turned by :data:`UUV_YAW_RATE_DPS` over them (plus :data:`TURN_MARGIN_DEG`).
    None without a residual: the located position alone may be long out of date.
    """
    shift = (pixel_then[0] - projected_then[0], pixel_then[1] - projected_then[1])
    if not (math.isfinite(shift[0]) and math.isfinite(shift[1])):
        return None
    u, v, px_per_m = projected_now[:3]
    sigma_m = reach_m(dt_s, speed_mps) / WINDOW_SIGMAS
    turn_deg = min(180.0, UUV_YAW_RATE_DPS * abs(dt_s) + TURN_MARGIN_DEG)
    return prediction_at(u, v, px_per_m, sigma_m, shift, turn_deg)
