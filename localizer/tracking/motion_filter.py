"""The reported pixel through waves filtered in time, the camera's motion the telemetry predicts taken out.

Through wind waves the tracked pixel jumps about the vehicle from frame to frame by a pixel or more (the waves
break its image up, the template's peak moves over it) while the vehicle's image moves by a fraction of a pixel: the
camera's motion, which the telemetry predicts (the session's prediction: the last sighting moved by what the camera
did since), and the vehicle's own, which is slow. :class:`MotionFilter` is a Kalman filter of the reported pixel
in the frame of the seafloor: each frame its estimate is moved by the camera's motion (the prediction less the
previous frame's tracked pixel) and by the vehicle's own image velocity (a state of the filter, so that a moving
vehicle is not lagged), and then drawn toward the frame's pixel by the gain the noises set:

- the measurement's: :attr:`MotionFilterParams.jitter_gain` × the tracked pixel's own jitter against the
  predictions (its running mean square per axis, :func:`~localizer.tracking.sigma.jitter2_px2`: the follows' offset
  from where the camera's motion put them), larger than that jitter because its errors last several frames;
- the vehicle's: a white acceleration, :attr:`MotionFilterParams.accel_m2ps3` (its spectral density, m²/s³), in
  pixels at the prediction's image scale.

Where the tracker jitters little the gain is high and the pixel nearly the tracker's; where it jitters a lot the
filter averages over more frames. The filter starts again after a frame without a pixel or a prediction (a loss, a
frame without a pose); its measured jitter is kept (the tracker's, not the track's). Causal: each frame's estimate
uses that frame and the ones before it, live as offline. The pixel's 1-sigma is left as it is.

Pure: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .sigma import jitter2_px2


@dataclass(frozen=True)
class MotionFilterParams:
    #: the vehicle's acceleration: white noise of this spectral density (m²/s³)
    accel_m2ps3: float = 0.01
    #: the measurement's variance per axis: the tracked pixel's jitter against the predictions (mean square), × this
    jitter_gain: float = 4.5
    #: the vehicle's image velocity when the filter starts: 0 with this 1-sigma (m/s)
    speed_mps: float = 0.5


class MotionFilter:
    """One target's reported pixel filtered (see the module doc); :meth:`restart` for a new target, :meth:`forget`
    after a frame without a pixel."""

    def __init__(self, params: MotionFilterParams = MotionFilterParams()) -> None:
        self.p = params
        self.restart()

    def restart(self) -> None:
        """A new target: its jitter measured again."""
        self._jitter2, self._follows = 0.0, 0
        self.forget()

    def forget(self) -> None:
        """A frame without a pixel (or not filtered): the filter starts again at the next one."""
        self._tracked: np.ndarray | None = None  # the previous frame's tracked pixel
        self._t = math.nan
        self._x = np.zeros(2)  # the estimate (u, v), pixels
        self._w = np.zeros(2)  # the vehicle's own image velocity, pixels/s
        self._P = np.zeros((2, 2))  # their covariance, per axis (position, velocity)

    def step(
        self,
        reported: tuple[float, float],
        tracked: tuple[float, float],
        predicted: tuple[float, float, float] | None,
        t_unix: float,
    ) -> tuple[float, float]:
        """The filtered pixel of a frame at ``t_unix``: ``reported``, the pixel to report unfiltered; ``tracked``,
        the tracker's own (where later predictions start from); ``predicted``, the session's prediction for the frame
        ``(u, v, px_per_m)`` (None: none)."""
        z = np.asarray(reported, dtype=float)
        here = np.asarray(tracked, dtype=float)
        last, self._tracked = self._tracked, here
        if predicted is None or not all(math.isfinite(x) for x in predicted):
            self.forget()
            return reported
        u, v, px_per_m = predicted
        self._follows += 1
        self._jitter2 = jitter2_px2(self._jitter2, self._follows, here[0] - u, here[1] - v)
        if last is None:  # a start: the frame's pixel, the vehicle's velocity unknown
            self._x, self._w, self._t = z, np.zeros(2), t_unix
            self._P = np.diag(
                [self.p.jitter_gain * self._jitter2, (self.p.speed_mps * px_per_m) ** 2]
            )
            return reported
        dt = t_unix - self._t
        self._t = t_unix
        step = np.array([[1.0, dt], [0.0, 1.0]])
        q = self.p.accel_m2ps3 * px_per_m**2
        P = step @ self._P @ step.T + q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        x = self._x + (np.array([u, v]) - last) + self._w * dt
        gain = P[:, 0] / (P[0, 0] + self.p.jitter_gain * self._jitter2)
        innovation = z - x
        self._x = x + gain[0] * innovation
        self._w = self._w + gain[1] * innovation
        self._P = P - np.outer(gain, P[0])
        return float(self._x[0]), float(self._x[1])
