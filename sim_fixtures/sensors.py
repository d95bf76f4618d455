"""The drone's own sensor errors: what its AHRS, gimbal, EKF position and barometer report minus the truth.

``[sensors]`` (:class:`~sim_fixtures.scenario.SensorsSpec`), all off by default. Every error here is
*reported − true*; the true motion (:mod:`sim_fixtures.motion`) and so the camera's true attitude, which
renders the image, stay the scenario's truth: a scenario with its sensors on shows the same scene in the same
video, only its telemetry differs (the mount is taken as held wherever the biased estimates put it).

What an ArduCopter with a stabilised gimbal reports, and how it is simulated here:

- **ATTITUDE** is the EKF's attitude. Its roll and pitch carry a constant tilt bias (accelerometer biases and
  an IMU misalignment the EKF cannot tell from a tilt: ``roll_bias_deg``, ``pitch_bias_deg``, 0.2–0.4°
  typical), its yaw the compass's bias (declination, hard and soft iron, motor currents: ``yaw_bias_deg``,
  1–2.5°), and each axis a slow wander (``wander_deg`` RMS, a first-order Gauss-Markov of correlation time
  ``wander_s``). They are added to the Euler angles (an airframe flies near level, where roll and pitch errors
  are the tilt about its forward and right axes). The body rates (the gyros) stay true. GLOBAL_POSITION_INT's
  ``hdg`` is the same biased heading.
- **A stabilised gimbal** (``[mount] kind = "stabilised"``) levels the camera with its own IMU and reports roll
  and pitch relative to the horizon that IMU finds: off by its own levelling error ``gimbal_level_deg``
  [roll, pitch], a tilt about the gimbal's own heading's forward and right axes (composed as rotations, so it
  holds straight down too, where Euler roll and yaw are one axis); the autopilot's tilt bias is not in it. The
  gimbal has no compass: a joint encoder measures its yaw relative to the airframe (exact), and its yaw from
  North is the autopilot's heading + that angle. So GIMBAL_DEVICE_ATTITUDE_STATUS with yaw in the vehicle frame
  (flags 32, as ArduPilot sends) carries the true relative yaw and the ground station adds ATTITUDE's biased
  yaw; with yaw in the earth frame (flags 64) the reported yaw is the autopilot's biased heading + the relative
  yaw; MOUNT_ORIENTATION's ``yaw`` is the relative yaw and ``yaw_absolute`` the biased heading + it. Either
  way the camera's yaw carries the compass's error (bias and wander) and its roll and pitch the gimbal's level
  error.
- **A servo mount** (ArduPilot ``MNT1_TYPE 1``) has no IMU: the autopilot stabilises it with its own biased
  attitude and reports its servo demands, relative to the airframe; composed with ATTITUDE the camera carries
  the AHRS's whole error. **A fixed camera** likewise.
- **GLOBAL_POSITION_INT** ``lat``, ``lon`` (the EKF's position): the receiver's slow error, a Gauss-Markov per
  axis of horizontal RMS ``gnss_walk_m`` and correlation ``gnss_walk_s`` (the EKF follows the receiver and
  smooths its noise: a walk, not white noise; smooth over seconds, :func:`slow_error`), plus ``gnss_white_m``
  of white noise. **GPS_RAW_INT**'s
  ``lat``, ``lon``: the same walk with a white draw of its own; its claims (``fix_type``, ``h_acc``, ``eph``)
  are ``[uav]``'s where given, else ``gnss_mode``'s (:func:`gnss_claim`). ``gnss_mode``: ``exact`` (none),
  ``rtk`` (RTK fixed, cm), ``plain`` (a receiver without corrections, a metre): see
  :data:`~sim_fixtures.scenario.GNSS_MODES`.
- **The barometer**: a slow wander (``baro_wander_m``, Gauss-Markov of ``baro_wander_s``) and white noise
  (``baro_noise_m``, the same draw in ``alt`` and ``relative_alt``) in the EKF's heights, on top of ``[uav]
  baro_bias_m`` and ``baro_drift_m`` (:func:`sim_fixtures.tlog.baro_error_m` has them all but the white).

The scene's error budget, the slow errors (biases, wanders, walks) at each frame, is written to
``truth_errors.csv`` (:func:`sim_fixtures.generate.write_truth_errors`); the white parts are new with each
message and not in it. Each error draws from its own random stream (``np.random.default_rng([seed, 505, k])``),
apart from the telemetry's: turning a sensor on leaves every other value of the session as it was, and with
all of them off the telemetry is byte for byte what it was without ``[sensors]``. ``draw`` (not 0) draws every one of
them (and ``[uav]``'s GNSS altitude errors) again, of the same sizes: another flight of the same drone over the
same scene.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

from .geometry import matrix_zyx, rotation_zyx
from .motion import Motion
from .scenario import GNSS_MODES, GnssMode, Scenario

STREAM = {
    "ahrs_wander": 1,
    "gnss_walk": 2,
    "gnss_white_ekf": 3,
    "gnss_white_raw": 4,
    "baro_wander": 5,
    "baro_noise": 6,
    "video_time": 7,
}
# a slow error is drawn this many times per correlation time, joined by a cubic spline
KNOTS_PER_CORRELATION = 10
MARGIN_S = 3.0  # ... over the telemetry's span and this much beyond


def stream(sc: Scenario, name: str):
    return np.random.default_rng([sc.seed, 505, STREAM[name], *drawn(sc)])


def drawn(sc: Scenario) -> list[int]:
    """What a sensor error's random stream is seeded with beside the scenario's seed: ``[sensors] draw`` where it is
    not 0 (0 keeps the streams, and so every session made before it, as they were)."""
    return [sc.sensors.draw] if sc.sensors.draw else []


def gauss_markov(rng, sigma: float, corr_s: float, step_s: float, shape: tuple) -> np.ndarray:
    """A stationary first-order Gauss-Markov process sampled every ``step_s`` along axis 0 of ``shape``.

    Each column is x[k+1] = φ·x[k] + σ·sqrt(1 − φ²)·w[k] with φ = exp(−step_s / corr_s), w white N(0, 1), started
    from its stationary law N(0, σ²): RMS ``sigma``, autocorrelation exp(−|Δt| / corr_s).
    """
    phi = np.exp(-step_s / corr_s)
    start = rng.normal(0.0, sigma, (1, *shape[1:]))
    w = rng.normal(0.0, sigma * np.sqrt(1.0 - phi * phi), shape)
    return lfilter([1.0], [1.0, -phi], w, axis=0, zi=phi * start)[0]


def slow_error(
    sc: Scenario, name: str, sigma: float, corr_s: float, axes: int, tau_s
) -> np.ndarray:
    """A slow error (RMS ``sigma`` per axis, correlation time ``corr_s``) at scenario times, (..., axes); zeros
    when ``sigma`` is 0.

    A Gauss-Markov process drawn from stream ``name`` at :data:`KNOTS_PER_CORRELATION` knots per correlation time
    over the telemetry's span, so every message and frame sees the same one, joined by a cubic spline: smooth
    over seconds, as an estimator's error is (a Gauss-Markov process itself would jitter at every step).
    """
    tau = np.asarray(tau_s, dtype=float)
    if sigma == 0:
        return np.zeros(tau.shape + (axes,))
    step = corr_s / KNOTS_PER_CORRELATION
    start, end = -sc.telemetry.lead_s - MARGIN_S - step, sc.duration_s + 1.0 + MARGIN_S + step
    knots = start + step * np.arange(max(4, int(np.ceil((end - start) / step)) + 1))
    values = gauss_markov(stream(sc, name), sigma, corr_s, step, (len(knots), axes))
    return CubicSpline(knots, values, axis=0)(tau)


# --- attitude ------------------------------------------------------------------------------------------


def ahrs_error_rpy(sc: Scenario, tau_s) -> np.ndarray:
    """ATTITUDE's error (reported − true roll, pitch, yaw; radians, (..., 3)): the biases and the slow wander."""
    s = sc.sensors
    bias = np.radians([s.roll_bias_deg, s.pitch_bias_deg, s.yaw_bias_deg])
    return bias + slow_error(sc, "ahrs_wander", np.radians(s.wander_deg), s.wander_s, 3, tau_s)


def levelled(sc: Scenario, rpy) -> np.ndarray:
    """What a stabilised gimbal reports (roll, pitch, yaw; radians, (..., 3)) when truly at ``rpy``: its horizon
    tilted by ``gimbal_level_deg`` about its heading's forward and right axes, R = R_z(yaw)·E·R_y(pitch)·R_x(roll).
    Its yaw is in whichever frame ``rpy``'s is. Unchanged for a servo mount (no IMU of its own) or no error."""
    rpy = np.asarray(rpy, dtype=float)
    level = sc.sensors.gimbal_level_deg
    if sc.mount.kind != "stabilised" or not any(level):
        return rpy
    tilt = rotation_zyx(*np.radians(level), 0.0)
    R = rotation_zyx(0.0, 0.0, rpy[..., 2]) * tilt * rotation_zyx(rpy[..., 0], rpy[..., 1], 0.0)
    yaw, pitch, roll = R.as_euler("ZYX").T
    return np.stack([roll, pitch, yaw], axis=-1).reshape(rpy.shape)


def reported_R_ned_from_gimbal(sc: Scenario, motion: Motion, tau_s) -> np.ndarray:
    """The camera's attitude (gimbal FRD in NED, (..., 3, 3)) as the telemetry states it, slow errors only:
    ATTITUDE composed with the mount's report as a ground station composes them (see the module's docstring)."""
    m = sc.mount
    body = motion.uav_rpy(tau_s) + ahrs_error_rpy(sc, tau_s)
    if m.attitude_source == "fixed":
        return matrix_zyx(body[..., 0], body[..., 1], body[..., 2]) @ matrix_zyx(
            *np.radians(m.fixed_rpy_deg)
        )
    g = levelled(sc, motion.reported_gimbal(tau_s))  # yaw relative to the vehicle
    if m.kind == "servo":
        return matrix_zyx(body[..., 0], body[..., 1], body[..., 2]) @ matrix_zyx(
            g[..., 0], g[..., 1], g[..., 2]
        )
    return matrix_zyx(0.0, 0.0, body[..., 2]) @ matrix_zyx(g[..., 0], g[..., 1], g[..., 2])


def camera_error_ned(R_reported, R_true) -> np.ndarray:
    """The reported camera attitude's error as a rotation vector in NED (radians, (..., 3)): the reported
    attitude is the true one turned by it (about North and East: the tilt; about Down: the yaw)."""
    R_err = np.asarray(R_reported) @ np.swapaxes(np.asarray(R_true), -1, -2)
    return Rotation.from_matrix(R_err.reshape(-1, 3, 3)).as_rotvec().reshape(R_err.shape[:-1])


# --- position and heights ----------------------------------------------------------------------------------


def gnss_mode(sc: Scenario) -> GnssMode:
    """The position's error model: ``gnss_mode``'s, with ``gnss_walk_m``, ``gnss_walk_s``, ``gnss_white_m`` where
    given (horizontal RMS, m; s)."""
    s, mode = sc.sensors, GNSS_MODES[sc.sensors.gnss_mode]
    return GnssMode(
        mode.walk_m if s.gnss_walk_m is None else s.gnss_walk_m,
        mode.walk_s if s.gnss_walk_s is None else s.gnss_walk_s,
        mode.white_m if s.gnss_white_m is None else s.gnss_white_m,
        mode.fix_type,
        mode.h_acc_m,
        mode.hdop,
    )


def gnss_claim(sc: Scenario) -> tuple[int, float, float]:
    """GPS_RAW_INT's ``(fix_type, h_acc_m, hdop)``: ``[uav]``'s where given, else ``[sensors] gnss_mode``'s."""
    u, mode = sc.uav, GNSS_MODES[sc.sensors.gnss_mode]
    return (
        mode.fix_type if u.gnss_fix_type is None else u.gnss_fix_type,
        mode.h_acc_m if u.gnss_h_acc_m is None else u.gnss_h_acc_m,
        mode.hdop if u.gnss_hdop is None else u.gnss_hdop,
    )


def position_error_ne_m(sc: Scenario, tau_s) -> np.ndarray:
    """The receiver's slow position error (north, east; m, (..., 2)) at scenario times, which the EKF follows."""
    g = gnss_mode(sc)
    return slow_error(sc, "gnss_walk", g.walk_m / np.sqrt(2.0), g.walk_s, 2, tau_s)


def position_white_ne_m(sc: Scenario, message: str, n: int) -> np.ndarray:
    """``n`` draws (n, 2) of the position's white noise (north, east; m) for ``message``: "ekf"
    (GLOBAL_POSITION_INT) or "raw" (GPS_RAW_INT); zeros when there is none."""
    sigma = gnss_mode(sc).white_m / np.sqrt(2.0)
    return (
        stream(sc, f"gnss_white_{message}").normal(0.0, 1.0, (n, 2)) * sigma
        if sigma
        else np.zeros((n, 2))
    )


def video_time_error_s(sc: Scenario) -> float:
    """video_frames.csv's times minus the frames' true exposures (s): ``[clock] video_time_error_s`` and a constant
    drawn from ``[sensors] video_time_sigma_s`` (one per flight: a latency known to that much)."""
    sigma = sc.sensors.video_time_sigma_s
    drawn_s = float(stream(sc, "video_time").normal(0.0, sigma)) if sigma else 0.0
    return sc.clock.video_time_error_s + drawn_s


def baro_wander_m(sc: Scenario, tau_s) -> np.ndarray:
    """The barometer's slow wander (m, positive: the EKF's heights read high) at scenario times."""
    s = sc.sensors
    return slow_error(sc, "baro_wander", s.baro_wander_m, s.baro_wander_s, 1, tau_s)[..., 0]


def baro_noise_m(sc: Scenario, n: int) -> np.ndarray:
    """``n`` draws of the EKF heights' white noise (m)."""
    s = sc.sensors
    return (
        stream(sc, "baro_noise").normal(0.0, s.baro_noise_m, n) if s.baro_noise_m else np.zeros(n)
    )


def ned_with_error(ned, error_ne_m) -> np.ndarray:
    """NED positions (..., 3) moved horizontally by ``error_ne_m`` (..., 2)."""
    ned = np.array(ned, dtype=float)
    ned[..., :2] += error_ne_m
    return ned


# --- what a platform with these sensors states ------------------------------------------------------------


def _rms(*values) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def platform_sigmas(sc: Scenario) -> dict[str, float]:
    """The ``[uncertainty]`` sigmas a platform with these sensors would state (its configuration: the typical size
    of each error, here the scenario's own), for the keys the sensors set; empty with the sensors off.

    ``tilt_deg``: the camera's tilt per axis, a stabilised gimbal's levelling error (its own IMU), else (a servo
    mount, a fixed camera) the AHRS's roll and pitch bias and wander; ``yaw_deg``: the compass's bias and wander;
    ``uav_horizontal_m``: the EKF position's walk and white noise (horizontal RMS; a stated error, not the
    receiver's claim); ``time_s``: the frames' time error; ``height_m``: the EKF heights' error, the take-off's bias, the barometer's wander (stationary:
    as large at any time as when the reference was set) and white noise; ``baro_drift_10min_m``: ``[uav]
    baro_drift_m``'s change over 10 minutes."""
    s, u = sc.sensors, sc.uav
    out = {}
    if s.roll_bias_deg or s.pitch_bias_deg or s.wander_deg or any(s.gimbal_level_deg):
        own_imu = sc.mount.kind == "stabilised" and sc.mount.attitude_source != "fixed"
        tilt = (
            _rms(*s.gimbal_level_deg)
            if own_imu
            else float(np.hypot(_rms(s.roll_bias_deg, s.pitch_bias_deg), s.wander_deg))
        )
        out["tilt_deg"] = tilt
    if s.yaw_bias_deg or s.wander_deg:
        out["yaw_deg"] = float(np.hypot(s.yaw_bias_deg, s.wander_deg))
    g = gnss_mode(sc)
    if g.walk_m or g.white_m:
        out["uav_horizontal_m"] = float(np.hypot(g.walk_m, g.white_m))
    if s.video_time_sigma_s:
        out["time_s"] = s.video_time_sigma_s
    if s.baro_wander_m or s.baro_noise_m:
        out["height_m"] = float(np.sqrt(u.baro_bias_m**2 + s.baro_wander_m**2 + s.baro_noise_m**2))
        out["baro_drift_10min_m"] = abs(u.baro_drift_m) * 600.0 / sc.duration_s
    return out


def has_slow_errors(sc: Scenario) -> bool:
    """Whether the scenario's telemetry has any slow error (the sensors' or ``[uav]``'s heights'): then the session
    gets ``truth_errors.csv``."""
    s, u = sc.sensors, sc.uav
    return bool(
        s.roll_bias_deg
        or s.pitch_bias_deg
        or s.yaw_bias_deg
        or s.wander_deg
        or any(s.gimbal_level_deg)
        or gnss_mode(sc).walk_m
        or s.baro_wander_m
        or u.baro_bias_m
        or u.baro_drift_m
        or u.gnss_alt_error_m
    )
