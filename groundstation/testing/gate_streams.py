"""Fix streams for the safety gates, with their truth: the failures the issue measured, and real motion.

Each stream is 30 Hz fixes of a UUV near (LAT0, LON0), each with its claimed ``h_acc_m``
(isotropic: sigma_n = sigma_e = h_acc / 1.2239, :func:`localizer.uncertainty.isotropic_sigma_m`) and a white error of :data:`NOISE_M` per axis
(the generated sessions' frame-to-frame scatter: consecutive fixes differ by 3–7 mm). A
stream says for each fix where the UUV truly is and whether the fix is the UUV at all
(``wrong``: the tracker on something else). Positions are built in metres north and east
and turned into degrees with a spherical Earth (the gate's own conversion is pymap3d's:
an independent one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear

from localizer.fix import Fix
from localizer.uncertainty import isotropic_sigma_m

LAT0, LON0 = 63.44, 10.40
M_PER_DEG = math.pi / 180.0 * 6_371_000.0
T0 = 1_763_800_000.0
HZ = 30.0
NOISE_M = 0.003
BEFORE_S = 2.0  # the UUV is tracked, stationary, this long before the failure


@dataclass
class Stream:
    name: str
    fixes: list[Fix]
    truth_ne: np.ndarray  # (n, 2) metres north, east: where the UUV is at each fix
    wrong: np.ndarray  # (n,) bool: the fix is not the UUV (a drift, a jump, a look-alike)
    # (n,) bool: a (re)acquisition starts at this fix (the first, the first after a loss)
    start: np.ndarray

    def real_after(self, seconds: float) -> np.ndarray:
        """Fixes of the UUV (ok, not wrong) more than ``seconds`` after its latest (re)acquisition began."""
        ok = np.array([f.ok for f in self.fixes])
        return ok & ~self.wrong & (seconds_since_start(self) > seconds + 1e-9)


def fix_at(t: float, north_m: float, east_m: float, h_acc_m: float, status: str = "ok") -> Fix:
    lat = LAT0 + north_m / M_PER_DEG
    lon = LON0 + east_m / (M_PER_DEG * math.cos(math.radians(LAT0)))
    s = float(isotropic_sigma_m(h_acc_m))
    if status != "ok":
        return Fix(t_unix=t, status=status)
    return Fix(
        t_unix=t,
        status="ok",
        u=640.0,
        v=360.0,
        lat=lat,
        lon=lon,
        alt_amsl_m=-1.0,
        depth_m=1.0,
        h_acc_m=h_acc_m,
        v_acc_m=0.5,
        sigma_n_m=s,
        sigma_e_m=s,
        cov_ne_m2=0.0,
    )


def _stream(name, truth_ne, seen_ne, h_acc_m, seed, status=None) -> Stream:
    n = len(truth_ne)
    status = status if status is not None else ["ok"] * n
    noise = np.random.default_rng(seed).normal(0.0, NOISE_M, (n, 2))
    fixes = [fix_at(T0 + i / HZ, *(seen_ne[i] + noise[i]), h_acc_m, status[i]) for i in range(n)]
    wrong = np.linalg.norm(seen_ne - truth_ne, axis=1) > 0
    ok = np.array([s == "ok" for s in status])
    start = ok & ~np.r_[False, ok[:-1]]
    return Stream(name, fixes, truth_ne, wrong & ok, start)


def _still(seconds: float) -> np.ndarray:
    return np.zeros((round(seconds * HZ), 2))


def ramp(h_acc_m: float, speed_mps: float = 0.35, seconds: float = 2.0, seed: int = 1) -> Stream:
    """The UUV stays put; from BEFORE_S on the fixes move away at ``speed_mps`` (0.7 m in 2 s), starting abruptly."""
    t = np.arange(1, round(seconds * HZ) + 1) / HZ
    seen = np.vstack([_still(BEFORE_S), np.stack([speed_mps * t, np.zeros_like(t)], axis=1)])
    return _stream(f"ramp {speed_mps:g} m/s", np.zeros_like(seen), seen, h_acc_m, seed)


def step(h_acc_m: float, size_m: float, seconds: float = 2.0, seed: int = 2) -> Stream:
    """The UUV stays put; from BEFORE_S on the fixes are ``size_m`` east of it."""
    seen = np.vstack([_still(BEFORE_S), _still(seconds) + [0.0, size_m]])
    return _stream(f"step {size_m:g} m", np.zeros_like(seen), seen, h_acc_m, seed)


def lookalike(
    h_acc_m: float, distance_m: float, loss_s: float = 1.0, seconds: float = 2.0, seed: int = 3
) -> Stream:
    """The UUV stays put; the tracker loses it for ``loss_s`` and comes back on something ``distance_m`` north."""
    n_loss = round(loss_s * HZ)
    seen = np.vstack([_still(BEFORE_S), _still(loss_s), _still(seconds) + [distance_m, 0.0]])
    status = ["ok"] * round(BEFORE_S * HZ) + ["lost"] * n_loss + ["ok"] * round(seconds * HZ)
    return _stream(
        f"look-alike {distance_m:g} m after {loss_s:g} s lost",
        np.zeros_like(seen),
        seen,
        h_acc_m,
        seed,
        status,
    )


def crossing(
    h_acc_m: float,
    miss_m: float = 0.3,
    speed_mps: float = 1.2,
    loss_s: float = 2 / 30,
    seconds: float = 3.0,
    seed: int = 6,
) -> Stream:
    """The UUV stays put; another vehicle crosses ``miss_m`` beside it at ``speed_mps``; the tracker loses the
    UUV for ``loss_s`` (two frames) as they meet and comes back on the other one (``second_vehicle``'s failure)."""
    n_loss, n_after = round(loss_s * HZ), round(seconds * HZ)
    t = np.arange(1, n_after + 1) / HZ + loss_s
    other = np.stack([np.full_like(t, miss_m), speed_mps * t], axis=1)
    seen = np.vstack([_still(BEFORE_S), _still(loss_s), other])
    status = ["ok"] * round(BEFORE_S * HZ) + ["lost"] * n_loss + ["ok"] * n_after
    return _stream(
        f"vehicle crossing {miss_m:g} m beside, lost {n_loss} frames",
        np.zeros_like(seen),
        seen,
        h_acc_m,
        seed,
        status,
    )


def accelerate(
    h_acc_m: float, accel_mps2: float, speed_mps: float, seconds: float = 3.0, seed: int = 4
) -> Stream:
    """The UUV rests, then accelerates north-east at ``accel_mps2`` from rest to ``speed_mps`` and goes on."""
    t = np.arange(1, round(seconds * HZ) + 1) / HZ
    t_full = speed_mps / accel_mps2
    d = np.where(
        t < t_full, 0.5 * accel_mps2 * t**2, 0.5 * accel_mps2 * t_full**2 + speed_mps * (t - t_full)
    )
    path = np.vstack([_still(BEFORE_S), np.stack([d, d], axis=1) / math.sqrt(2.0)])
    return _stream(
        f"accelerating at {accel_mps2:g} m/s² to {speed_mps:g} m/s", path, path, h_acc_m, seed
    )


def turn(
    h_acc_m: float, speed_mps: float, accel_mps2: float, seconds: float = 6.0, seed: int = 5
) -> Stream:
    """The UUV goes round a circle at ``speed_mps``, its centripetal acceleration ``accel_mps2``."""
    r = speed_mps**2 / accel_mps2
    a = speed_mps / r * np.arange(round(seconds * HZ)) / HZ
    path = np.stack([r * np.sin(a), r * (1.0 - np.cos(a))], axis=1)
    return _stream(f"turning at {speed_mps:g} m/s, radius {r:.2f} m", path, path, h_acc_m, seed)


def offer(
    gate, stream: Stream, lose, thrusters=None, pushing=lambda t: False, outputs_hz: float = 10.0
) -> np.ndarray:
    """Offer each fix as it is made (0.05 s later); ``lose()`` on a lost frame. Accepted mask, per fix.

    With ``thrusters`` (a :class:`~localizer.thrusters.Thrusters` that knows a vectored frame), ArduSub's
    outputs arrive at ``outputs_hz`` from 2 s before the stream: the four horizontal motors at 1500 µs, or
    at 1580 µs (forward, 20 % of full) when ``pushing(t)`` says the UUV pushes at that arrival."""
    out = np.zeros(len(stream.fixes), dtype=bool)
    t_out = stream.fixes[0].t_unix - 2.0
    for i, f in enumerate(stream.fixes):
        now = f.t_unix + 0.05
        while thrusters is not None and t_out <= now:
            pulse = 1580 if pushing(t_out) else 1500
            thrusters.outputs(
                t_out, {1: 3000 - pulse, 2: 3000 - pulse, 3: pulse, 4: pulse, 5: 1620, 6: 1620}
            )
            t_out += 1.0 / outputs_hz
        if f.ok:
            out[i] = gate.check(f, now) is None
        else:
            lose()
    return out


def vectored_thrusters():
    """ArduSub's outputs as a BlueROV2's SITL reports its parameters: FRAME_CONFIG 1, SERVO1-6 motors 1-6."""
    from localizer.thrusters import Thrusters

    th = Thrusters()
    th.param("FRAME_CONFIG", 1.0)
    for n in range(1, 17):
        th.param(f"SERVO{n}_FUNCTION", 32.0 + n if n <= 6 else 0.0)
    return th


def seconds_since_start(stream: Stream) -> np.ndarray:
    """Per fix: seconds since the latest (re)acquisition began."""
    t = np.array([f.t_unix for f in stream.fixes])
    begun = np.maximum.accumulate(np.where(stream.start, t, -np.inf))
    return t - begun


def bounded_fit_residual_m(
    speed_mps: float, accel_mps2: float, before_s: float = 1.0, after_s: float = 1.0
) -> float:
    """The smallest largest-residual (m) of a 1-D motion with |acceleration| ≤ ``accel_mps2`` fitted to a
    noise-free 30 Hz stream at rest, then moving at ``speed_mps`` from one frame to the next (scipy's
    bounded least squares over the accelerations between frames)."""
    t = np.arange(round((before_s + after_s) * HZ)) / HZ
    t0 = t[round(before_s * HZ) - 1]
    z = np.where(t > t0, speed_mps * (t - t0), 0.0)
    dt = 1.0 / HZ
    # x = x0 + v0·t + Σ a_j · (what a_j, held over its frame, adds later)
    M = np.zeros((len(t), len(t) + 1))
    M[:, 0], M[:, 1] = 1.0, t
    for j in range(len(t) - 1):
        tau = t - t[j]
        M[:, 2 + j] = np.where(
            tau <= 0, 0.0, np.where(tau < dt, tau**2 / 2, dt**2 / 2 + dt * (tau - dt))
        )
    bound = np.r_[np.inf, np.inf, np.full(len(t) - 1, accel_mps2)]
    r = lsq_linear(M, z, bounds=(-bound, bound))
    return float(np.abs(M @ r.x - z).max())
