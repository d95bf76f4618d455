"""The tracked pixel through waves, held to the vehicle's silhouette: what is reported, never what is tracked.

Through wind waves the template match walks over the vehicle's broken-up image: its point wanders by a share of the
vehicle's size over seconds (the template learns the wave-distorted mean, and that mean slides), though from frame to
frame it follows the waves that move the vehicle's image as a whole. The vehicle's *silhouette* does not wander: it
stands out of the seafloor darker than it (its sides and shaded parts; the top face inside it is filled in), and its
centroid follows the place the vehicle is seen at through the waves, noisier from frame to frame (a caustic, a
wave that breaks the outline up) but without the slow walk.

:class:`CentroidSteer` takes the slow part of each from where it is sure: the reported pixel is the tracker's, moved
by the silhouette's offset from it averaged over :attr:`CentroidParams.follow_s` (the offset's wave-to-wave noise
averaged, the tracker's walk followed), less that offset as it was over the first :attr:`CentroidParams.anchor_s`
in waves (the *anchor*): the selected point (the top face's centre) is where it lies on the silhouette, which an
oblique view or a shadow puts off the silhouette's centroid. A walk within :attr:`CentroidParams.walk_sigmas` of
the average's own scatter (the offset's frame-to-frame change, averaged) is taken as noise and that much of it is
left out: where the tracker does not walk (light winds) its pixel is kept. After a loss the average starts again
from the re-acquired frame's offset, its scatter still the offset's noise measured before (the silhouette's, not the
track's: one frame's offset is as noisy after a loss as before it); the anchor stays (the vehicle, not the tracker,
sets it).

The tracker's decisions (its predictions, its ok and lost frames) are untouched: the steer is applied to the result a
:class:`~localizer.tracking.session.TrackingSession` step returned, after it, and only where the matcher reads the
sea state as waves (:attr:`CentroidParams.waves_from`, until the reading is nil again) from the start, within
``anchor_s`` of the target's first frame: a still surface's reading rises for a while after a loss (a turbid dive),
which is not waves. On a still surface nothing is measured and the reported pixel is the tracker's. Its 1-sigma
(``sigma_px``) is kept.

Wherever the steer applies, the steered pixel is then filtered in time, the camera's motion the session's
prediction gives taken out (:class:`~localizer.tracking.motion_filter.MotionFilter`; ``motion``: its parameters,
None the defaults): the tracker's jumps from frame to frame through waves averaged, the vehicle's own motion
followed. The filter starts again where the steer's average does (a loss, a still surface).

:func:`silhouette_centroid` finds the silhouette around a pixel: in a square of :attr:`CentroidParams.reach` times
the vehicle's apparent length, the pixels darker than the seafloor (the square's rim, beyond
:attr:`CentroidParams.rim` of its half-size: its median and robust sigma) by :attr:`CentroidParams.dark_sigmas`,
closed and their holes filled, the parts within :attr:`CentroidParams.near` times the length of the pixel.

Pure: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from . import TrackResult
from .motion_filter import MotionFilter, MotionFilterParams


@dataclass(frozen=True)
class CentroidParams:
    reach: float = 1.2  # the square's half-size, × the vehicle's apparent length
    rim: float = 0.8  # the seafloor: the square's pixels beyond this share of its half-size
    #: silhouette: darker than the seafloor's median by this many of its robust sigmas
    dark_sigmas: float = 2.0
    blur_px: float = 1.0  # the square smoothed first (Gaussian sigma, pixels): the codec's and the sensor's noise
    near: float = 0.5  # the silhouette's parts within this share of the length of the tracked pixel
    follow_s: float = 0.25  # the offset's running average's time constant (s)
    #: the offset over this long after the selection: where the selected point lies on the silhouette
    anchor_s: float = 2.0
    #: the matcher's waves reading from which the steer applies (until it is nil again)
    waves_from: float = 0.5
    #: a walk is followed beyond this many of its average's own sigmas (the offset's noise averaged); less is noise
    walk_sigmas: float = 4.0


def silhouette_centroid(
    grey: np.ndarray, u: float, v: float, length_px: float, p: CentroidParams = CentroidParams()
) -> tuple[float, float] | None:
    """The centroid (pixels) of the vehicle's dark silhouette around ``(u, v)`` in the frame ``grey`` (H, W; a BGR
    frame's grey levels are read), the vehicle ``length_px`` long in the image; None where nothing near ``(u, v)``
    stands out darker."""
    half = max(2, round(p.reach * length_px))
    side = 2 * half + 1
    square = cv2.getRectSubPix(grey, (side, side), (float(u), float(v)), patchType=cv2.CV_32F)
    if square.ndim == 3:
        square = cv2.cvtColor(square, cv2.COLOR_BGR2GRAY)
    if p.blur_px > 0:
        square = cv2.GaussianBlur(square, (0, 0), p.blur_px)
    dy, dx = np.mgrid[-half : half + 1, -half : half + 1]
    r = np.hypot(dx, dy)
    floor = square[r > p.rim * half]
    median = float(np.median(floor))
    sigma = 1.4826 * float(np.median(np.abs(floor - median))) + 1e-6
    dark = (square - median) < -p.dark_sigmas * sigma
    # here, not at the top: scipy.ndimage takes ~0.17 CPU-s to import, which every ``skyfix process`` and live
    # service paid on its main thread before its first frame, though only a session in waves gets here
    from scipy import ndimage

    dark = ndimage.binary_fill_holes(ndimage.binary_closing(dark))
    dark = ndimage.binary_opening(dark)
    parts, n = ndimage.label(dark)
    if n == 0:
        return None
    near = np.unique(parts[(r < p.near * length_px) & dark])
    inside = np.isin(parts, near[near > 0])
    if not inside.any():
        return None
    return float(u + dx[inside].mean()), float(v + dy[inside].mean())


class CentroidSteer:
    """One target's reported pixel steered by its silhouette (see the module doc); :meth:`restart` for a new
    target."""

    def __init__(
        self,
        params: CentroidParams = CentroidParams(),
        motion: MotionFilterParams | None = None,
    ) -> None:
        self.p = params
        self.filter = MotionFilter(motion or MotionFilterParams())
        #: the last frame's result before the filter (steered): what the offline smoothed track is made from
        self.unfiltered: TrackResult | None = None
        self.restart()

    def restart(self) -> None:
        """A new target: its anchor measured again."""
        self._wavy = False
        self._first_t = math.nan  # the target's first ok frame
        self._anchor_t = (
            math.nan
        )  # its first wavy ok frame, when that came within anchor_s of the first
        self._anchor_sum, self._anchors = np.zeros(2), 0
        # the offset's mean square change from frame to frame, and their count: the silhouette's noise, kept
        # through losses (a re-acquired frame's offset is as noisy as any)
        self._noise2, self._noises = 0.0, 0
        self.filter.restart()
        self._forget()

    def _forget(self) -> None:
        """After a loss, or while the surface is still: the running average started again."""
        self._offset: np.ndarray | None = None  # the offset's running average
        self._last: np.ndarray | None = None  # the last frame's offset
        self._t = math.nan
        self._alpha = 1.0  # the running average's last step's weight
        self.filter.forget()

    def after(self, session, image: np.ndarray, result: TrackResult, t_unix: float) -> TrackResult:
        """:meth:`step` for the ``result`` a :class:`~localizer.tracking.session.TrackingSession` ``session`` just
        returned for the frame ``image``: its matcher's waves reading, its prediction's vehicle length."""
        expected = session.prediction
        return self.step(
            image,
            result,
            t_unix,
            session.target.waves,
            expected.width_px if expected is not None else math.nan,
            (expected.u, expected.v, expected.px_per_m) if expected is not None else None,
        )

    def step(
        self,
        grey: np.ndarray,
        result: TrackResult,
        t_unix: float,
        waves: float,
        length_px: float,
        predicted: tuple[float, float, float] | None = None,
    ) -> TrackResult:
        """``result`` of the frame ``grey`` (H, W; a BGR frame is taken as its grey levels) at ``t_unix``, its pixel
        steered when ``waves`` (the matcher's reading, 0..1) says the sea state is waves and the anchor is known,
        and filtered in time wherever the steer applies (:class:`~localizer.tracking.motion_filter.MotionFilter`);
        ``length_px``: the vehicle's apparent length (NaN: unknown, the mean side of the result's box);
        ``predicted``: the session's prediction for the frame, ``(u, v, px_per_m)`` (None: none, nothing
        filtered)."""
        steered = self.unfiltered = self._steered(grey, result, t_unix, waves, length_px)
        if not self._steering(result):
            return steered
        u, v = self.filter.step((steered.u, steered.v), (result.u, result.v), predicted, t_unix)
        return replace(steered, u=u, v=v)

    def _steering(self, result: TrackResult) -> bool:
        """Whether the steer applies to the frame just stepped: a pixel, in waves read from the start."""
        return result.ok and result.box is not None and self._wavy and math.isfinite(self._anchor_t)

    def _steered(
        self, grey: np.ndarray, result: TrackResult, t_unix: float, waves: float, length_px: float
    ) -> TrackResult:
        """:meth:`step`'s pixel before the filter."""
        if not result.ok or result.box is None:
            self._forget()
            return result
        self._wavy = waves >= self.p.waves_from or (self._wavy and waves > 0.0)
        if math.isnan(self._first_t):
            self._first_t = t_unix
        if not self._wavy:  # a still surface: nothing measured
            self._forget()
            return result
        if math.isnan(self._anchor_t):
            # waves from the start only: a wobble after a loss on a still surface does not count
            if t_unix - self._first_t > self.p.anchor_s:
                return result
            self._anchor_t = t_unix
        anchoring = t_unix - self._anchor_t <= self.p.anchor_s
        if not math.isfinite(length_px):
            length_px = 0.5 * (result.box[2] + result.box[3])
        centroid = silhouette_centroid(grey, result.u, result.v, length_px, self.p)
        if centroid is not None:
            offset = np.array(centroid) - (result.u, result.v)
            if anchoring:
                self._anchor_sum += offset
                self._anchors += 1
            if self._last is not None:
                self._noises += 1
                self._noise2 += (
                    float(np.sum((offset - self._last) ** 2)) - self._noise2
                ) / self._noises
            self._last = offset
            if self._offset is None:
                self._offset = offset
            else:
                self._alpha = 1.0 - math.exp(-(t_unix - self._t) / self.p.follow_s)
                self._offset += self._alpha * (offset - self._offset)
            self._t = t_unix
        if anchoring or self._offset is None or not self._anchors:
            return result
        walk = self._offset - self._anchor_sum / self._anchors
        # the average's own scatter: the offset's (half its mean square change) × an average's share of it
        noise = math.sqrt(0.5 * self._noise2 * self._alpha / (2.0 - self._alpha))
        length = float(np.hypot(*walk))
        keep = max(0.0, 1.0 - self.p.walk_sigmas * noise / length) if length > 0 else 0.0
        return replace(
            result, u=result.u + float(walk[0]) * keep, v=result.v + float(walk[1]) * keep
        )
