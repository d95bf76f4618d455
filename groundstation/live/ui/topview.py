"""The map of the web page: a top view in metres north and east of a fixed origin.

The origin is the UAV's first reported position (its latitude and longitude are
shown). :meth:`TopView.snapshot` places the UAV and the camera's footprint on the
water at the newest frame's time: the image's border, sampled along each edge, is
projected onto the water surface with that frame's camera pose
(:func:`localizer.pose.camera_pose`, :func:`localizer.ray.pixel_to_offset` at depth 0);
rays above the horizon never reach the water and are left out (``horizon``). Each
UUV's track (:class:`UuvTrack`, one per UUV of the run, :attr:`TopView.tracks`; the first is
the view's own ``on_fix`` and ``points_since``) is every ``ok`` fix (at most one per
``min_dt_s``) with its horizontal accuracy, numbered so that each page is sent only what it
has not seen; all tracks share the view's origin.
:meth:`TopView.gate_view` places the safety gates' track of the UUV (its state, filtered
position, velocity and covariance, and its reach while a target is being acquired).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from localizer.calibration import Calibration
from localizer.fix import Fix
from localizer.geodesy import geodetic_to_ned
from localizer.pose import camera_pose
from localizer.ray import pixel_to_offset
from localizer.telemetry import Telemetry

EDGE_SAMPLES = 8  # points per image edge: the lens's distortion bends the footprint's sides


def border_pixels(width: int, height: int, n: int = EDGE_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """The image's outline (pixel edges, OpenCV's pixel centres), clockwise from the top-left corner: top edge first."""
    s = np.linspace(0.0, 1.0, n, endpoint=False)
    left, top, right, bottom = -0.5, -0.5, width - 0.5, height - 0.5
    u = np.concatenate([left + s * width, np.full(n, right), right - s * width, np.full(n, left)])
    v = np.concatenate([np.full(n, top), top + s * height, np.full(n, bottom), bottom - s * height])
    return u, v


class UuvTrack:
    """Pipeline sink (``on_fix``) keeping one UUV's track on a :class:`TopView` (its origin, its newest frame)."""

    def __init__(self, view: TopView, keep: int, min_dt_s: float):
        self.view = view
        self.min_dt_s = min_dt_s
        # seq, t, lat, lon, h_acc
        self.track: deque[tuple[int, float, float, float, float]] = deque(maxlen=keep)
        self._seq = 0

    def on_fix(self, fix: Fix, info) -> None:
        if math.isfinite(fix.t_unix):
            self.view._frame_t = fix.t_unix
        if not fix.ok or (self.track and fix.t_unix - self.track[-1][1] < self.min_dt_s):
            return
        self._seq += 1
        self.track.append((self._seq, fix.t_unix, fix.lat, fix.lon, fix.h_acc_m))

    def points_since(self, seq: int) -> list[list[float]]:
        """Track points after ``seq``: ``[seq, north_m, east_m, h_acc_m, t]`` each."""
        new = (
            [p for p in self.track if p[0] > seq] if self.track and self.track[-1][0] > seq else []
        )
        if not new or self.view.origin is None:
            return []
        a = np.array(new)
        n, e, _ = geodetic_to_ned(a[:, 2], a[:, 3], 0.0, *self.view.origin, 0.0)
        return [
            [
                int(p[0]),
                round(float(ni), 3),
                round(float(ei), 3),
                round(float(p[4]), 3),
                round(p[1], 3),
            ]
            for p, ni, ei in zip(new, np.atleast_1d(n), np.atleast_1d(e), strict=True)
        ]


class TopView:
    """The map: :meth:`snapshot` is the UAV and the footprint now; ``tracks``: one :class:`UuvTrack` per UUV
    (``uuvs`` of them), each a sink of its UUV's pipeline; the view's own ``on_fix``/``points_since`` are the
    first's."""

    def __init__(
        self,
        cal: Calibration,
        tel: Telemetry,
        keep: int = 3000,
        min_dt_s: float = 0.1,
        uuvs: int = 1,
    ):
        self.cal = cal
        self.tel = tel
        self.min_dt_s = min_dt_s
        self.origin: tuple[float, float] | None = None
        self._frame_t: float | None = None
        self._border = border_pixels(cal.camera.width, cal.camera.height)
        self.tracks = [UuvTrack(self, keep, min_dt_s) for _ in range(max(1, uuvs))]
        self.track = self.tracks[0].track

    def on_fix(self, fix: Fix, info) -> None:
        self.tracks[0].on_fix(fix, info)

    def points_since(self, seq: int) -> list[list[float]]:
        """The first UUV's track points after ``seq``: ``[seq, north_m, east_m, h_acc_m, t]`` each."""
        return self.tracks[0].points_since(seq)

    def snapshot(self, now: float) -> dict:
        """The UAV and the camera's footprint at the newest frame's time (or now, before any frame)."""
        t = self._frame_t if self._frame_t is not None else now
        pose = camera_pose(self.cal, self.tel, t)
        out = {
            "t": round(t, 3),
            "pose": str(pose.status[0]),
            "uav": None,
            "footprint": None,
            "horizon": False,
            "height_m": None,
        }
        lat, lon = float(pose.lat_deg[0]), float(pose.lon_deg[0])
        if not (math.isfinite(lat) and math.isfinite(lon)):
            out["origin"] = self._origin_json()
            return out
        if self.origin is None:
            self.origin = (lat, lon)
        n, e, _ = geodetic_to_ned(lat, lon, 0.0, *self.origin, 0.0)
        uav = np.array([float(n), float(e)])
        out["uav"] = [round(c, 3) for c in uav]
        out["origin"] = self._origin_json()
        if pose.status[0] != "ok":
            return out
        out["height_m"] = round(float(pose.height_m[0]), 2)
        u, v = self._border
        off, reaches = pixel_to_offset(
            self.cal.camera,
            pose.R_ned_from_cv[0],
            u,
            v,
            pose.height_m[0],
            0.0,
            self.cal.water.refractive_index,
        )
        good = reaches & np.all(np.isfinite(off), axis=-1)
        out["horizon"] = bool(not good.all())
        if good.sum() >= 3:
            pts = off[good] + pose.cam_offset_ned_m[0, :2] + uav
            out["footprint"] = [[round(float(a), 3), round(float(b), 3)] for a, b in pts]
            # the first points are the image's top edge
            out["top_edge"] = int(good[:EDGE_SAMPLES].sum())
        return out

    def gate_view(self, gates: dict | None) -> dict | None:
        """The safety gates' state and track (their status, ``gps_input.gates``) on the map: position in metres
        north and east of the origin, velocity, 1-sigma covariance and, while acquiring, the UUV's reach."""
        if not gates:
            return None
        out = {"state": gates["state"], "reach_m": gates["reach_m"], "track": None}
        tr = gates["track"]
        if tr is not None and self.origin is not None:
            n, e, _ = geodetic_to_ned(tr["lat"], tr["lon"], 0.0, *self.origin, 0.0)
            out["track"] = {
                "n": round(float(n), 3),
                "e": round(float(e), 3),
                "vn": tr["vn_mps"],
                "ve": tr["ve_mps"],
                "sigma_n": tr["sigma_n_m"],
                "sigma_e": tr["sigma_e_m"],
                "cov_ne": tr["cov_ne_m2"],
            }
        return out

    def _origin_json(self) -> dict | None:
        return (
            None
            if self.origin is None
            else {"lat": round(self.origin[0], 8), "lon": round(self.origin[1], 8)}
        )
