"""The telemetry a fix needs, buffered on the clocks it arrives with.

UAV messages are stored on the autopilot's boot clock (seconds), which is
precise and monotonic; a frame's UNIX time is mapped onto it at query time via
:class:`~localizer.timeline.VehicleClock`. Depth comes with UNIX times. Angles
in radians, positions in degrees and metres.
"""

from __future__ import annotations

import numpy as np

from .calibration import Timing
from .timeline import Series, VehicleClock


def _refuse(series: Series) -> bool:
    """Count a sample refused for its value (NaN fails every range check too)."""
    series.rejected += 1
    return False


class Telemetry:
    """Buffers for ATTITUDE, GLOBAL_POSITION_INT, the gimbal message and depth.

    ``keep_s`` bounds the history kept (live service); None keeps all (offline).
    """

    def __init__(self, timing: Timing | None = None, keep_s: float | None = None):
        timing = timing or Timing()
        self.clock = VehicleClock(on_reboot=self._drop_boot_clock_samples)
        # roll, pitch, yaw of the UAV body (FRD in NED), boot seconds
        self.attitude = Series("aaa", timing.attitude_gap_s, timing.attitude_hold_s, keep_s)
        # lat_deg, lon_deg, alt_amsl_m, relative_alt_m, boot seconds
        self.position = Series("llll", timing.position_gap_s, timing.position_hold_s, keep_s)
        # GIMBAL_DEVICE_ATTITUDE_STATUS: q (w, x, y, z), flags, boot seconds
        self.gimbal = Series("qqqqs", timing.gimbal_gap_s, timing.gimbal_hold_s, keep_s)
        # MOUNT_ORIENTATION: roll, pitch, yaw relative to the vehicle, boot seconds
        self.mount = Series("aaa", timing.gimbal_gap_s, timing.gimbal_hold_s, keep_s)
        # UUV depth below the surface (m, positive down), UNIX seconds
        self.depth = Series("l", timing.depth_gap_s, timing.depth_hold_s, keep_s)
        # the MAVLink component whose time_boot_ms the UAV buffers are on, and other components' clocks
        self.autopilot_component: int | None = None
        self._other_clocks: dict[int, VehicleClock] = {}

    def to_autopilot_boot_ms(self, component: int, time_boot_ms, receive_unix_s: float) -> float | None:
        """Another component's ``time_boot_ms`` on the autopilot's boot clock (a MAVLink gimbal keeps its own).

        Each clock's least ``receive − boot`` offset includes the same least link
        delay, which cancels in their difference. None until the autopilot's is known.
        """
        clock = self._other_clocks.setdefault(component, VehicleClock())
        clock.add_receive(time_boot_ms, receive_unix_s)
        own = self.clock.receive_offset_s
        if own is None:
            return None
        return time_boot_ms + (clock.receive_offset_s - own) * 1000.0

    def _drop_boot_clock_samples(self) -> None:
        """The autopilot rebooted: samples on its old boot clock would be matched to wrong frames."""
        for series in (self.attitude, self.position, self.gimbal, self.mount):
            series.clear()

    def _on_clock(self, time_boot_ms, receive_unix_s: float | None) -> None:
        """Tell the clock about a sample that passed its checks (so garbage cannot fake a reboot)."""
        if receive_unix_s is not None:
            self.clock.add_receive(time_boot_ms, receive_unix_s)

    def add_attitude(self, time_boot_ms, roll, pitch, yaw, receive_unix_s: float | None = None) -> bool:
        """ATTITUDE (radians); ``receive_unix_s`` also feeds the clock once the values pass."""
        if not all(abs(a) <= 2 * np.pi for a in (roll, pitch, yaw)):
            return _refuse(self.attitude)
        self._on_clock(time_boot_ms, receive_unix_s)
        return self.attitude.append(time_boot_ms / 1000.0, (roll, pitch, yaw))

    def add_position(self, time_boot_ms, lat_deg, lon_deg, alt_amsl_m, relative_alt_m,
                     receive_unix_s: float | None = None) -> bool:
        """GLOBAL_POSITION_INT in degrees and metres; lat/lon 0/0 (no GNSS) is refused."""
        if (not (-90 <= lat_deg <= 90 and -180 <= lon_deg <= 180) or (lat_deg == 0 and lon_deg == 0)
                or not np.all(np.isfinite((alt_amsl_m, relative_alt_m)))):
            return _refuse(self.position)
        self._on_clock(time_boot_ms, receive_unix_s)
        return self.position.append(time_boot_ms / 1000.0, (lat_deg, lon_deg, alt_amsl_m, relative_alt_m))

    def add_gimbal(self, time_boot_ms, q_wxyz, flags, receive_unix_s: float | None = None) -> bool:
        """GIMBAL_DEVICE_ATTITUDE_STATUS quaternion (w, x, y, z), which must be near unit length."""
        q = np.asarray(q_wxyz, dtype=float)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 0.1:
            return _refuse(self.gimbal)
        self._on_clock(time_boot_ms, receive_unix_s)
        return self.gimbal.append(time_boot_ms / 1000.0, (*q, flags))

    def add_mount(self, time_boot_ms, roll_deg, pitch_deg, yaw_deg, receive_unix_s: float | None = None) -> bool:
        """MOUNT_ORIENTATION (degrees; yaw relative to the vehicle)."""
        if not all(abs(a) <= 360.0 for a in (roll_deg, pitch_deg, yaw_deg)):
            return _refuse(self.mount)
        self._on_clock(time_boot_ms, receive_unix_s)
        return self.mount.append(time_boot_ms / 1000.0, np.radians((roll_deg, pitch_deg, yaw_deg)))

    def add_depth(self, t_unix, depth_m) -> bool:
        if not -5.0 <= depth_m <= 11000.0:
            return _refuse(self.depth)
        return self.depth.append(t_unix, (depth_m,))
