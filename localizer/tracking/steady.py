"""A box checked over several frames: whether a vehicle-sized object stands out of the water in it while it is followed.

One frame's :func:`~localizer.tracking.detect.detect` does not tell a small, deep UUV from the seafloor through wind
waves: the waves break the vehicle's image up (it may score under ``min_saliency``) and focus the sunlight into
caustics on the seafloor, bright blobs that score as high as a vehicle. Over a fraction of a second the two differ:
a caustic and the waves' distortion move and flicker with the waves, the vehicle stays where it is followed.
:class:`SteadyWindow` holds the mean of the saliencies (:func:`~localizer.tracking.detect.saliency`) of the window
around a box across frames, each frame's window centred where the box is followed to in it (the tracker's pixel,
relative to where it started); :meth:`SteadyWindow.detect` asks of that mean what
:func:`~localizer.tracking.detect.detect` asks of one frame's (:func:`~localizer.tracking.detect.standing_out`), the
outline taken in the latest frame. The saliencies are averaged, not the images: a vehicle turning while it is
followed blurs into a disc in a mean image, and has no outline there.

Pure: no I/O, no clock.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from . import Prediction
from .detect import Detection, DetectParams, Saliency, saliency, standing_out


class SteadyWindow:
    """The mean saliency of the window ``detect`` reads for ``prediction`` (its pixel: where the box is in the first
    frame), over frames whose window is taken where the followed point moved since the first frame (``start_uv``:
    the followed point there)."""

    def __init__(self, prediction: Prediction, start_uv: tuple[float, float], params: DetectParams):
        self.prediction, self.params, self.start_uv = prediction, params, start_uv
        p = prediction
        radius = params.search_sigmas * p.sigma_px + math.hypot(p.width_px, p.height_px) / 2
        self._half = 1 + math.ceil(
            radius + params.background_sides * math.sqrt(p.width_px * p.height_px)
        )
        # the prediction in a window's pixels (its centre)
        self._centred = Prediction(
            self._half, self._half, p.width_px, p.height_px, p.sigma_px, p.px_per_m
        )
        self._sum: np.ndarray | None = None
        self._latest: tuple[np.ndarray, Saliency, float, float] | None = None
        self.frames = 0

    def add(self, frame: np.ndarray, followed_uv: tuple[float, float]) -> None:
        """One frame (BGR or grey) and the followed point in it: its window's saliencies join the mean."""
        cu = self.prediction.u + followed_uv[0] - self.start_uv[0]
        cv_ = self.prediction.v + followed_uv[1] - self.start_uv[1]
        side = 2 * self._half + 1
        window = cv2.getRectSubPix(frame, (side, side), (cu, cv_))
        found = saliency(window, self._centred, self.params)
        if found is None:
            return
        self._sum = found.map if self._sum is None else self._sum + found.map
        self._latest = (window, found, cu - self._half, cv_ - self._half)
        self.frames += 1

    def peak(self) -> tuple[float, float]:
        """The place of the mean saliency's best (its block's centre), in the latest frame's pixels: where the
        object stands out over the frames, not in the latest one alone (whose outline waves may break up)."""
        _, latest, x0, y0 = self._latest
        _, _, _, (j, i) = cv2.minMaxLoc(self._sum)
        return float(latest.bu[j]) + x0, float(latest.bv[i]) + y0

    def detect(self) -> Detection | None:
        """The object standing out of the mean saliency (``params``' ``min_saliency`` and ``distinct``), outlined
        in the latest frame, in that frame's pixels; None: none, or no frame."""
        if self._latest is None:
            return None
        window, latest, x0, y0 = self._latest
        mean = Saliency(
            (self._sum / self.frames).astype(np.float32),
            latest.bu,
            latest.bv,
            latest.f,
            latest.diag,
        )
        found = standing_out(window, mean, self.params)
        if found is None:
            return None
        x, y, w, h = found.box
        return Detection(
            (round(x + x0), round(y + y0), w, h), found.u + x0, found.v + y0, found.saliency
        )
