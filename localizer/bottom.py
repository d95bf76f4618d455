"""The drone's pose biases from the static seafloor: bundle adjustment of bottom features.

A biased pose puts the same floor point in different places as the drone moves; this
module finds the biases that put it back in one place. Inputs: tracks of floor points
(the pixel of one point in many frames), each frame's reported camera pose (attitude,
horizontal position, height above the water) and the water's refractive index. Solved
by robust nonlinear least squares (:func:`scipy.optimize.least_squares`):

- the **attitude error** (reported − true, as ``sim_fixtures`` writes it in ``truth_errors.csv``): the
  reported camera attitude is the true one turned by the rotation vector (NED)
  ``ε = R_z(ψ)·(tilt_fwd, tilt_right, 0) + (0, 0, yaw)``, ``R_reported = exp([ε]×) · R_true`` (both
  ``R_ned_from_cv``): a **tilt** about the level forward and right axes of a per-frame *bias frame* of
  heading ``ψ`` (``bias_heading_rad``: a stabilised gimbal levels the camera with its own IMU, so its
  levelling error is about the camera's own heading, :func:`camera_heading_rad`; a servo mount or a
  fixed camera carries the AHRS's tilt bias, about the airframe's heading; 0: about North and East),
  and a **heading** error ``yaw`` about Down (the compass's bias: a compass reading 2° high has
  ``yaw = +2°``);
- the **floor depth** below the water (unless given), the floor taken flat and level;
- each feature's horizontal position;
- a slowly varying correction ``w(t)`` to the reported horizontal position (the GNSS walk),
  piecewise linear in time with knots every ``knot_spacing_s``: ``true = reported + w``.
  Its increments have a random-walk prior (``walk_rate_m``/√s) about 0, or, given the reported
  velocity (the EKF's, from the receiver's Doppler, which a slow position error is not in), about what
  the velocity says the position should have moved less what it did (given candidate rates, ``walk_rates_m``, the
  rate is the one of the largest marginal likelihood, :func:`walk_rate_log_evidence`, and the walk's sigmas take
  the spread of the walks of the rates the recording cannot tell apart); its **mean over the knots
  is held at 0**: a constant offset of everything is invisible in the bottom, so the
  corrected track keeps the GNSS's mean position (the absolute offset needs a reference); the fit starts from the
  walk the velocity tells (a plain receiver's decimetres), not from none;
- with ``white_m`` > 0, each frame's own offset ``o_k`` on top of the walk (``true = reported + w(t) + o_k``), with a
  white prior of that 1-sigma per axis: the reported position's white noise (a receiver's few centimetres, which
  2-second knots cannot follow and which would otherwise bend the floor to fit them). A uniform shift of one frame's
  floor points is all it can absorb: the biases show in how the points move *across* the frames, which is not white.
- with ``tilt_wander_rad`` > 0, the tilt's slow wander ``δ(t)`` about its constant part (``tilt + δ(t)``, an AHRS's
  wander): values at the walk's knots, linear between them, with the prior of a first-order Gauss-Markov process of
  that 1-sigma and correlation time ``tilt_wander_s`` (each knot given the one before), their **mean held at 0** (the
  constant part is the tilt's mean over the recording). A slow tilt change shifts the floor as the walk does: it is
  told apart where the walk is held (RTK, an exact velocity), else it stays within its prior.

A residual is a floor point's ground position seen from one frame minus the feature's,
turned into pixels by the inverse of the ground-per-pixel Jacobian at that observation
(a reprojection error, to first order) and divided by ``pixel_px``. The robust loss
(``soft_l1``) downweights what does not stay on the floor (the UUV, glints).

What makes the biases observable: a feature sliding through the image is seen at changing
angles; a tilt bias moves its ground position by ``≈ (h + D/n)·δ·sec²θ`` (the constant part
is a shift of all features, the ``sec²`` part is not), a heading bias rotates the footprint
about the nadir, which the bottom alone cannot tell from rotating the trajectory: the position
prior (RTK: tight; plain GNSS: loose) is what separates a heading bias from a GNSS walk. A
hovering drone leaves all of them unobservable: their priors (``tilt_rad``, ``yaw_rad``)
come back as their sigmas. Not trusting what is left (a body-frame tilt seen through the heading's swings
depends on the bias frame being right), :attr:`BottomEstimate.estimated` also asks that the features slid
across a good part of the image (:data:`MIN_SLIDE_SHARE`).

Covariances are from the Jacobian at the solution (Gauss-Newton, the features eliminated by
their Schur complement), the observations' variance the residuals' own: the a-posteriori variance factor
``χ²/dof`` of the inlying residuals (in :attr:`Priors.pixel_px` sigmas, ``dof`` their number less the parameters'),
not floored at ``pixel_px``, which is the weighting's guess (and the robust loss's scale), not a measurement. The
white per-point noise is what ``χ²/dof`` measures (over thousands of degrees of freedom, to about a per cent); what
the residuals do not show (an error the features or the walk take up, a pull along the tracks) is not white
per-point noise, and a floor on it would size it as the white noise's share whatever it is: what of it moves the
biases is what the parts' spread takes (below), and :mod:`groundstation.offline.bottom` does not apply a fit whose
residuals are too large (``MAX_RMS_PX``). The priors' rows keep their own variances (the estimator's covariance
``H⁻¹·(χ²/dof·H_obs + H_prior)·H⁻¹``, :func:`_covariance`): where a prior alone tells a parameter its sigma stays
the prior's, where the bottom tells it the sigma follows the residuals. The covariances take the residuals as white,
and what is not (a floor light that drags the points, waves, a walk the knots cannot follow) they do not
see: asked for ``parts``, :func:`estimate` also solves each of that many consecutive stretches of the
recording alone and widens the biases' and the floor depth's sigmas by the standard error of the parts' mean
(``hypot(σ, spread/√P)``, ``spread`` the sample standard deviation of the P parts' values): the whole fit holds
all the parts' data, so its error beyond its own sigma is that of their mean, not one part's. An estimate whose
thirds disagree is not claimed; a bias that changes during the recording (which one part's scatter would hold,
each frame's error being its change from the mean) is held only to a third of its variance with three parts.
Such a bias can also pull the whole fit away from every part (a compass that steps by 3° in the last third moved
the whole fit's forward tilt by 3.2° while the three parts agreed on it within 0.07°): where the whole fit is more
than :data:`WHOLE_APART` times its own and the standard error's sigmas from the parts' mean, that distance is added
to the bias's sigma too.
Radians, metres, seconds.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from .camera import Camera, pixel_to_ray
from .refraction import offset_from_ray

if TYPE_CHECKING:
    import scipy.sparse as sp

#: a bias is "estimated" when its posterior 1-sigma is below this share of its prior's ...
ESTIMATED_SHARE = 0.3
#: ... and the features slid across at least this share of the image's diagonal (:func:`slide_share`)
MIN_SLIDE_SHARE = 0.15
#: a part of the recording (``estimate(parts=...)``) with fewer features seen twice in it gives no estimate
MIN_PART_FEATURES = 10
#: The whole fit's distance from its parts' mean, in its own sigma and the parts' standard error together, beyond which
#: the distance is added to its sigma (a model that does not hold over the whole recording).
WHOLE_APART = 3.0
#: floor depths tried for the start (m), geometric
_DEPTH_GRID_M = np.geomspace(0.2, 60.0, 48)
_ANGLE_STEP = 1e-5  # rad, finite difference of the global parameters
_DEPTH_STEP = 1e-4  # m
_PIXEL_STEP = 0.5  # px, finite difference of the ground-per-pixel Jacobian
_HEIGHT_STEP = 0.01  # m, finite difference of the heights' effect (:func:`_per_height`)
N_GLOBAL = 4  # tilt_fwd, tilt_right, yaw, floor depth


@dataclass(frozen=True)
class Priors:
    """Prior 1-sigmas and the model's settings."""

    tilt_rad: float = np.radians(3.0)  # each tilt component's prior about 0
    yaw_rad: float = np.radians(10.0)  # the heading bias's
    walk_rate_m: float = 0.2  # GNSS walk: 1-sigma of its change over 1 s, growing with √time (m/√s)
    # candidate walk rates (m/√s): given, the fit at ``walk_rate_m`` is made again at the one of the largest
    # marginal likelihood (:func:`walk_rate_log_evidence`); empty: ``walk_rate_m`` is kept
    walk_rates_m: tuple[float, ...] = ()
    knot_spacing_s: float = 2.0  # the walk's knots
    # the reported position's white noise, 1-sigma per axis (m): per-frame offsets; 0: none
    white_m: float = 0.0
    # the tilt's slow wander about its constant bias, 1-sigma per axis (rad), a first-order Gauss-Markov process of
    # correlation time ``tilt_wander_s``, at the walk's knots; 0: the tilt is constant
    tilt_wander_rad: float = 0.0
    tilt_wander_s: float = 60.0
    # the reported heights' wander about their level, 1-sigma (m), a first-order Gauss-Markov process of correlation
    # time ``height_wander_s`` (a barometer's): the floor does not tell it, the walk takes up part of it, and the
    # walk's sigmas take that part (:func:`_walk_per_height`); 0: the heights' error is taken as constant
    height_wander_m: float = 0.0
    height_wander_s: float = 30.0
    # a tracked floor point's 1-sigma in u and v the fit weighs them by; the covariance takes the residuals' own
    pixel_px: float = 0.7
    floor_depth_m: float | None = None  # given: not estimated
    floor_depth_prior_m: float = 100.0  # estimated: its (weak) prior's 1-sigma about the start
    loss_scale: float = 2.0  # soft_l1's scale, in pixel sigmas


@dataclass
class FramePoses:
    """The reported camera of K frames (arrays of length K)."""

    t_s: np.ndarray  # any clock
    R_ned_from_cv: np.ndarray  # (K, 3, 3)
    camera_ne_m: np.ndarray  # (K, 2) the camera's horizontal position in a local frame
    height_m: np.ndarray  # the camera above the water
    # the tilt bias's frame (see the module doc); None: 0 (North, East)
    bias_heading_rad: np.ndarray | None = None
    # (K, 2) the reported horizontal velocity; None: not used
    velocity_ne_mps: np.ndarray | None = None
    # (K, 2) the reported position the velocity is of (the drone's, where the camera sits on a lever arm that turns
    # with it); None: the camera's
    velocity_origin_ne_m: np.ndarray | None = None


@dataclass
class Observations:
    """M observations: frame ``frame`` (index into :class:`FramePoses`) saw feature ``feature`` at pixel (u, v)."""

    frame: np.ndarray
    feature: np.ndarray
    u: np.ndarray
    v: np.ndarray


@dataclass
class BottomEstimate:
    """The solution. The attitude error (reported − true): ``tilt_rad`` = (forward, right) about the bias frame,
    ``yaw_rad`` about Down; ``cov_bias`` the 3×3 covariance of (tilt_fwd, tilt_right, yaw) (rad²)."""

    tilt_rad: np.ndarray
    yaw_rad: float
    cov_bias: np.ndarray
    floor_depth_m: float
    sigma_floor_depth_m: float  # 0 when given
    knot_t_s: np.ndarray  # (J,)
    walk_ne_m: np.ndarray  # (J, 2)
    sigma_walk_ne_m: np.ndarray  # (J, 2): relative to the mean (which is held at 0)
    features_ne_m: np.ndarray  # (F, 2)
    rms_px: float  # of the inlying residuals, each of u and v, pixels
    # how far the features slid in the image (:func:`slide_share`), share of its diagonal
    slide_share: float
    n_observations: int
    n_features: int
    n_frames: int
    inliers: np.ndarray = field(repr=False)  # (M,) bool: residual within 3 loss scales
    priors: Priors = field(default_factory=Priors, repr=False)
    #: (2J, 2J) the walk's covariance, knots' (north, east) in turn (m²); empty: not known
    cov_walk_m2: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    #: (P, 4) each part's tilt_fwd, tilt_right, yaw (rad) and floor depth (m) alone, NaN where it gave none; the
    #: sigmas above include the standard error of their mean (see the module doc); (0, 4): not asked
    parts: np.ndarray = field(default_factory=lambda: np.zeros((0, N_GLOBAL)), repr=False)
    #: (R, 2) the candidate walk rates (m/√s) and their log marginal likelihoods (:attr:`Priors.walk_rates_m`; the
    #: chosen one is ``priors.walk_rate_m``); (0, 2): none tried
    walk_rate_evidence: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)), repr=False)
    #: (J, 2) the tilt's wander about ``tilt_rad`` at the knots (:attr:`Priors.tilt_wander_rad`); (0, 2): none
    tilt_wander_rad: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)), repr=False)
    #: (J, 2) the walk the reported velocity told at the knots (:func:`velocity_drift` on the fit's frames, about its
    #: mean), which the walk's prior follows; (0, 2): the frames had no velocity
    velocity_walk_ne_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)), repr=False)
    #: (3,) how the tilt_fwd, tilt_right and yaw found move (rad) per metre the reported heights read high
    #: (:func:`_per_height`): the floor does not tell the height, and its sigmas do not include this
    bias_per_height_rad: np.ndarray = field(default_factory=lambda: np.zeros(3), repr=False)
    #: (2J, 3) how the walk's knots (north, east in turn) move (m) with the tilt_fwd, tilt_right and yaw found (per
    #: rad: the inverse Gauss-Newton Hessian's block of the walk with them over theirs, whatever the observations'
    #: variance): what an error of the biases beyond the fit's own sigma puts into the walk (:meth:`with_walk_error`);
    #: (0, 3): not known
    walk_per_bias_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)

    @property
    def sigma_tilt_rad(self) -> float:
        """The tilt's 1-sigma: the larger axis of its 2×2 covariance."""
        return float(np.sqrt(np.max(np.linalg.eigvalsh(self.cov_bias[:2, :2]))))

    @property
    def sigma_yaw_rad(self) -> float:
        return float(np.sqrt(self.cov_bias[2, 2]))

    @property
    def tilt_estimated(self) -> bool:
        """Whether the bottom told the tilt (its sigma well below the prior's, the features slid), not the prior."""
        return (
            self.slide_share >= MIN_SLIDE_SHARE
            and self.sigma_tilt_rad < ESTIMATED_SHARE * self.priors.tilt_rad
        )

    @property
    def yaw_estimated(self) -> bool:
        return (
            self.slide_share >= MIN_SLIDE_SHARE
            and self.sigma_yaw_rad < ESTIMATED_SHARE * self.priors.yaw_rad
        )

    @property
    def estimated(self) -> bool:
        return self.tilt_estimated or self.yaw_estimated

    def error_rotvec(self, bias_heading_rad) -> np.ndarray:
        """The attitude error ``ε`` (..., 3) (reported − true, NED) at frames of these bias-frame headings."""
        return bias_rotvec(self.tilt_rad, self.yaw_rad, bias_heading_rad)

    def correction(self, bias_heading_rad) -> np.ndarray:
        """``exp(−[ε]×)`` (..., 3, 3) per frame: ``R_true = correction · R_reported``."""
        return rodrigues(-self.error_rotvec(bias_heading_rad))

    def tilt_at(self, t_s) -> np.ndarray:
        """The tilt (..., 2) (forward, right) at times ``t_s``: the constant bias and its wander (held beyond the
        first and last knots)."""
        if not len(self.tilt_wander_rad):
            return np.broadcast_to(self.tilt_rad, np.shape(t_s) + (2,))
        return self.tilt_rad + _interp_knots(self.knot_t_s, self.tilt_wander_rad, t_s)

    def walk_at(self, t_s) -> np.ndarray:
        """The position correction (..., 2) at times ``t_s`` (held beyond the first and last knots)."""
        return _interp_knots(self.knot_t_s, self.walk_ne_m, t_s)

    def sigma_walk_at(self, t_s) -> np.ndarray:
        return _interp_knots(self.knot_t_s, self.sigma_walk_ne_m, t_s)

    def with_walk_error(self, moves_m) -> BottomEstimate:
        """This estimate with the walk's covariance and sigmas widened by errors the fit's own covariance does not
        hold: ``moves_m`` (2J, C), each column how far one independent 1-sigma error moves the knots (north, east in
        turn, m), e.g. :attr:`walk_per_bias_m` times the biases' error beyond the fit's sigma (the parts' spread)."""
        moves = np.asarray(moves_m, dtype=float).reshape(len(self.cov_walk_m2), -1)
        cov = self.cov_walk_m2 + moves @ moves.T
        return replace(
            self, cov_walk_m2=cov, sigma_walk_ne_m=np.sqrt(np.diagonal(cov)).reshape(-1, 2)
        )

    def describe(self) -> str:
        """One line: what was estimated and how sure."""
        tilt = (
            f"tilt fwd {np.degrees(self.tilt_rad[0]):+.2f}° right {np.degrees(self.tilt_rad[1]):+.2f}° "
            f"± {np.degrees(self.sigma_tilt_rad):.2f}°"
            + ("" if self.tilt_estimated else " (not observable)")
        )
        if len(self.tilt_wander_rad):
            tilt += (
                f", wandering up to {np.degrees(np.abs(self.tilt_wander_rad).max()):.2f}° about it"
            )
        yaw = (
            f"heading {np.degrees(self.yaw_rad):+.2f}° ± {np.degrees(self.sigma_yaw_rad):.2f}°"
            + ("" if self.yaw_estimated else " (not observable)")
        )
        depth = f"floor {self.floor_depth_m:.2f} m" + (
            f" ± {self.sigma_floor_depth_m:.2f}" if self.sigma_floor_depth_m > 0 else " (given)"
        )
        walk, sigma_walk = np.hypot(*self.walk_ne_m.T), np.hypot(*self.sigma_walk_ne_m.T)
        if len(self.parts):
            heading = "/".join(
                "—" if np.isnan(y) else f"{np.degrees(y):+.2f}" for y in self.parts[:, 2]
            )
            depth += (
                f" (sigmas with the {len(self.parts)} parts' spread; their headings {heading}°)"
            )
        per_m = np.degrees(self.bias_per_height_rad)
        yaw += (
            f"; per metre the camera's height reads high they move tilt {per_m[0]:+.2f}°/{per_m[1]:+.2f}°, "
            f"heading {per_m[2]:+.2f}° (the floor does not tell the height)"
        )
        return (
            f"{tilt}; {yaw}; {depth}; position walk up to {walk.max():.2f} m ± {sigma_walk.max():.3f} m "
            "about the GNSS's mean; "
            f"{self.n_features} floor features, {self.n_observations} observations in {self.n_frames} frames, "
            f"{self.rms_px:.2f} px RMS"
        )


def bias_rotvec(tilt_rad, yaw_rad, bias_heading_rad) -> np.ndarray:
    """The attitude error's rotation vector (..., 3) in NED: the tilt (forward, right; (2,) or one per frame (..., 2))
    about the axes of bias frames of these headings, the yaw about Down (see the module doc)."""
    psi = np.asarray(bias_heading_rad, dtype=float)
    tilt = np.asarray(tilt_rad, dtype=float)
    a, b = tilt[..., 0], tilt[..., 1]
    c, s = np.cos(psi), np.sin(psi)
    fwd, right, yaw = np.broadcast_arrays(a * c - b * s, a * s + b * c, float(yaw_rad))
    return np.stack([fwd, right, yaw], axis=-1)


def in_bias_frame(rotvec_ned, bias_heading_rad) -> np.ndarray:
    """A NED rotation vector (..., 3) as (forward, right, down) about bias frames of these headings: the inverse of
    :func:`bias_rotvec` (units kept)."""
    r, psi = np.asarray(rotvec_ned, dtype=float), np.asarray(bias_heading_rad, dtype=float)
    c, s = np.cos(psi), np.sin(psi)
    return np.stack(
        [r[..., 0] * c + r[..., 1] * s, -r[..., 0] * s + r[..., 1] * c, r[..., 2]], axis=-1
    )


def camera_heading_rad(R_ned_from_cv) -> np.ndarray:
    """The heading (radians from North) of cameras with no roll about their optical axis: the direction their image
    right (cv x, level then) makes 90° to the right of; defined straight down too, where the optical axis has none."""
    right = np.asarray(R_ned_from_cv, dtype=float)[..., :, 0]
    return np.arctan2(-right[..., 0], right[..., 1])


def slide_share(camera: Camera, obs: Observations) -> float:
    """How far the features slid through the image: per feature the farthest any of its pixels lies from its first,
    median over the observations (a feature counts as often as it was seen: a drifting light that breaks the tracks
    into many short ones does not hide how far the floor went), as a share of the image's diagonal."""
    f = np.asarray(obs.feature, dtype=int)
    order = np.argsort(f, kind="stable")
    f, u, v = f[order], np.asarray(obs.u, float)[order], np.asarray(obs.v, float)[order]
    first = np.searchsorted(f, f)  # each observation's feature's first row
    reach = np.hypot(u - u[first], v - v[first])
    farthest = np.zeros(f.max() + 1)
    np.maximum.at(farthest, f, reach)
    return float(np.median(farthest[f]) / np.hypot(camera.width, camera.height))


def rodrigues(w) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors (..., 3) (radians)."""
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=-1)
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = w[..., 2], -w[..., 1], w[..., 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(theta > 1e-12, np.sin(theta) / theta, 1.0)[..., None, None]
        b = np.where(theta > 1e-12, (1 - np.cos(theta)) / theta**2, 0.5)[..., None, None]
    return np.eye(3) + a * K + b * (K @ K)


def _rotate(w, d):
    """Vectors ``d`` (M, 3) rotated by rotation vectors ``w`` (M, 3) (Rodrigues' formula, no matrices)."""
    theta = np.linalg.norm(w, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(theta > 1e-12, np.sin(theta) / theta, 1.0)
        b = np.where(theta > 1e-12, (1 - np.cos(theta)) / theta**2, 0.5)
    wxd = np.cross(w, d)
    return d + a * wxd + b * np.cross(w, wxd)


def _velocity_steps(poses: FramePoses, knots) -> np.ndarray:
    """The walk's expected change between consecutive knots (J − 1, 2): the reported velocity integrated
    (trapezoids) less the reported position's change, fitted by the knots' piecewise-linear curve (least squares: the
    position's white noise averages over a knot's frames); zeros without a velocity."""
    if poses.velocity_ne_mps is None:
        return np.zeros((len(knots) - 1, 2))
    origin = poses.camera_ne_m if poses.velocity_origin_ne_m is None else poses.velocity_origin_ne_m
    drift, _ = velocity_drift(poses.t_s, poses.velocity_ne_mps, origin, knots)
    return np.diff(drift, axis=0)


def velocity_drift(
    t_s, velocity_ne_mps, position_ne_m, knots, curve_ne_m=None
) -> tuple[np.ndarray, np.ndarray]:
    """What the reported velocity says of the reported position (frames in any order, NaN rows ignored): the
    velocity integrated (trapezoids, in time order) less the position's change, true − reported up to a constant,
    fitted by the knots' piecewise-linear curve (J, 2), and each frame's remainder (K, 2) about that curve (NaN where
    the frame had none): the position's white noise, negated (``true = reported + walk + remainder`` where the
    velocity is exact), which the knots are too far apart to follow. ``curve_ne_m`` (J, 2) given: the remainder is
    about that curve instead (up to a constant: the remainder's mean is taken off), e.g. the one a fit on other
    frames of the same recording followed (:attr:`BottomEstimate.velocity_walk_ne_m`): a curve fitted to these
    frames' white noise would differ from it by that noise's share in the knots."""
    t = np.asarray(t_s, dtype=float)
    vel, pos = np.asarray(velocity_ne_mps, float), np.asarray(position_ne_m, float)
    good = np.flatnonzero(
        np.isfinite(t) & np.all(np.isfinite(vel), 1) & np.all(np.isfinite(pos), 1)
    )
    order = good[np.argsort(t[good])]
    t, vel, pos = t[order], vel[order], pos[order]
    travelled = np.concatenate(
        [np.zeros((1, 2)), np.cumsum(0.5 * (vel[1:] + vel[:-1]) * np.diff(t)[:, None], axis=0)]
    )
    basis = _interp_knots(knots, np.eye(len(knots)), t)  # (K, J): each frame's weights of the knots
    target = travelled - (pos - pos[0])  # true − reported, up to a constant
    if curve_ne_m is None:
        drift, *_ = np.linalg.lstsq(basis, target, rcond=None)
    else:
        drift = np.asarray(curve_ne_m, float)
        drift = drift + np.mean(target - basis @ drift, axis=0)
    remainder = np.full((len(np.asarray(t_s)), 2), np.nan)
    remainder[order] = target - basis @ drift
    return drift, remainder


def white_noise_m(poses: FramePoses) -> float | None:
    """The reported position's white noise (1-sigma per axis, m) seen against the reported velocity: the scatter of
    the second differences, frame to frame, of the velocity's integral less the position's change (a walk, smooth
    over seconds, leaves them nearly nil; white noise of sigma σ makes them σ·√6), median absolute deviation.
    None without a velocity or with fewer than 5 frames."""
    if poses.velocity_ne_mps is None or len(poses.t_s) < 5:
        return None
    t = np.asarray(poses.t_s, dtype=float)
    order = np.argsort(t)
    t, vel, pos = (
        t[order],
        np.asarray(poses.velocity_ne_mps, float)[order],
        np.asarray(poses.camera_ne_m, float)[order],
    )
    step = 0.5 * (vel[1:] + vel[:-1]) * np.diff(t)[:, None] - np.diff(pos, axis=0)
    second = np.diff(step, axis=0).ravel()
    return float(1.4826 * np.median(np.abs(second - np.median(second))) / np.sqrt(6.0))


def _interp_knots(knot_t, values, t):
    t = np.asarray(t, dtype=float)
    return np.stack([np.interp(t, knot_t, values[:, k]) for k in range(values.shape[1])], axis=-1)


def knot_times(t_s, spacing_s: float) -> np.ndarray:
    """Knots from the first to the last frame, at most ``spacing_s`` apart (at least two)."""
    t0, t1 = float(np.min(t_s)), float(np.max(t_s))
    n = max(2, int(np.ceil((t1 - t0) / spacing_s)) + 1)
    return np.linspace(t0, t1, n)


class _Problem:
    """The least-squares problem: parameters ``[tilt_fwd, tilt_right, yaw, depth, walk (J×2), frame offsets (K×2,
    none when ``white_m`` is 0), features (F×2)]``."""

    def __init__(
        self, camera: Camera, n_water, poses: FramePoses, obs: Observations, priors: Priors
    ):
        self.n_water, self.priors = n_water, priors
        k = np.asarray(obs.frame, dtype=int)
        self.k, self.f = k, np.asarray(obs.feature, dtype=int)
        self.M, self.F = len(k), int(self.f.max()) + 1
        heading = (
            poses.bias_heading_rad
            if poses.bias_heading_rad is not None
            else np.zeros(len(poses.t_s))
        )
        self.psi = np.asarray(heading, dtype=float)[k]
        self.h = np.asarray(poses.height_m, dtype=float)[k]
        self.cam = np.asarray(poses.camera_ne_m, dtype=float)[k]
        R = np.asarray(poses.R_ned_from_cv, dtype=float)[k]
        u, v = np.asarray(obs.u, float), np.asarray(obs.v, float)
        rays = pixel_to_ray(
            camera, np.stack([u, u + _PIXEL_STEP, u]), np.stack([v, v, v + _PIXEL_STEP])
        )
        # the reported rays in NED, and of the moved pixels
        self.d0 = np.einsum("mij,kmj->kmi", R, rays)
        self.h = np.broadcast_to(self.h, (3, self.M))
        t = np.asarray(poses.t_s, dtype=float)
        self.knots = knot_times(t, priors.knot_spacing_s)
        self.J = len(self.knots)
        tk = t[k]
        j = np.clip(np.searchsorted(self.knots, tk, side="right") - 1, 0, self.J - 2)
        self.j = j
        self.s = np.clip((tk - self.knots[j]) / (self.knots[j + 1] - self.knots[j]), 0.0, 1.0)
        self.walk_steps = _velocity_steps(poses, self.knots)
        # the walk the velocity tells, about its mean: where the fit starts (a plain receiver's walks decimetres)
        walk0 = np.concatenate([np.zeros((1, 2)), np.cumsum(self.walk_steps, axis=0)])
        self.walk0 = walk0 - walk0.mean(axis=0)
        self.K = len(t) if priors.white_m > 0 else 0
        self.W = self.J if priors.tilt_wander_rad > 0 else 0
        self.first_wander = N_GLOBAL + 2 * self.J + 2 * self.K
        self.first_feature = self.first_wander + 2 * self.W
        self.depth_fixed = priors.floor_depth_m
        self.depth0 = (
            priors.floor_depth_m if priors.floor_depth_m is not None else self._start_depth()
        )
        self.n_params = self.first_feature + 2 * self.F

    # --- geometry ---------------------------------------------------------------------------------
    def offsets(self, g, wander=None):
        """Horizontal offsets (3, M, 2) from the camera of each observation's pixel and of the pixel moved by
        :data:`_PIXEL_STEP` in u and in v, for globals ``g`` and the tilt's wander at the knots (J, 2) if any."""
        tilt = g[:2]
        if wander is not None and len(wander):
            tilt = (
                tilt + (1 - self.s)[:, None] * wander[self.j] + self.s[:, None] * wander[self.j + 1]
            )
        # the true rays: the reported ones turned back by the error
        w = -bias_rotvec(tilt, g[2], self.psi)
        d = _rotate(np.broadcast_to(w, self.d0.shape), self.d0)
        off, _ = offset_from_ray(d, self.h, np.full(self.h.shape, g[3]), self.n_water)
        return off

    def ground(self, g, walk_knots, white=None, wander=None):
        """Ground positions (M, 2) of every observation and the 2×2 pixels-per-metre matrices (M, 2, 2) there
        (the inverse of d ground / d pixel), for globals ``g``, walk knots (J, 2), frame offsets (K, 2) and the tilt's
        wander at the knots (J, 2) if any."""
        off = self.offsets(g, wander)
        Jg = np.stack([(off[1] - off[0]) / _PIXEL_STEP, (off[2] - off[0]) / _PIXEL_STEP], axis=-1)
        walk = (1 - self.s)[:, None] * walk_knots[self.j] + self.s[:, None] * walk_knots[self.j + 1]
        if white is not None and len(white):
            walk = walk + white[self.k]
        return self.cam + walk + off[0], np.linalg.inv(Jg)

    def _start_depth(self) -> float:
        """The grid depth at which each feature's ground positions scatter least in pixels (zero biases, the walk the
        velocity tells)."""
        best, best_cost = _DEPTH_GRID_M[0], np.inf
        for depth in _DEPTH_GRID_M:
            gp, A = self.ground(np.array([0.0, 0.0, 0.0, depth]), self.walk0)
            cost = np.median(
                np.linalg.norm(np.einsum("mij,mj->mi", A, gp - self._means(gp)[self.f]), axis=-1)
            )
            if cost < best_cost:
                best, best_cost = depth, cost
        return float(best)

    def _means(self, gp):
        """Each feature's mean ground position (F, 2)."""
        mean = np.zeros((self.F, 2))
        np.add.at(mean, self.f, gp)
        return mean / np.maximum(np.bincount(self.f, minlength=self.F), 1)[:, None]

    # --- the residuals and their Jacobian ---------------------------------------------------------
    def unpack(self, x):
        g = x[:N_GLOBAL].copy()
        if self.depth_fixed is not None:
            g[3] = self.depth_fixed
        walk = x[N_GLOBAL : N_GLOBAL + 2 * self.J].reshape(self.J, 2)
        white = x[N_GLOBAL + 2 * self.J : self.first_wander].reshape(self.K, 2)
        feats = x[self.first_feature :].reshape(self.F, 2)
        return g, walk, white, feats

    def wander(self, x):
        """The tilt's wander at the knots (J, 2) in ``x``; (0, 2) when the tilt is constant."""
        return x[self.first_wander : self.first_feature].reshape(self.W, 2)

    def observation_residuals(self, x, with_whitening: bool = False):
        """Residuals (M, 2) in pixel sigmas; ``with_whitening``: also d residual / d ground (M, 2, 2)."""
        g, walk, white, feats = self.unpack(x)
        gp, A = self.ground(g, walk, white, self.wander(x))
        Aw = A / self.priors.pixel_px
        r = np.einsum("mij,mj->mi", Aw, gp - feats[self.f])
        return (r, Aw) if with_whitening else r

    def prior_residuals(self, x):
        g, walk, white, _ = self.unpack(x)
        p = self.priors
        rate = p.walk_rate_m * np.sqrt(np.diff(self.knots))[:, None]
        depth = (g[3] - self.depth0) / p.floor_depth_prior_m if self.depth_fixed is None else x[3]
        return np.concatenate(
            [
                [g[0] / p.tilt_rad, g[1] / p.tilt_rad, g[2] / p.yaw_rad, depth],
                ((np.diff(walk, axis=0) - self.walk_steps) / rate).ravel(),
                walk.mean(axis=0) / 1e-3,  # the gauge: the correction's mean is 0
                (white / p.white_m).ravel() if self.K else [],
                self._wander_prior_rows() @ self.wander(x).ravel() if self.W else [],
            ]
        )

    def _wander_prior_rows(self) -> np.ndarray:
        """The tilt wander's prior as linear residuals of its knots (2J − 2 + 2 rows, 2J columns): each knot given the
        one before as a first-order Gauss-Markov process says (``(δ_j − φ·δ_{j−1}) / (σ·√(1 − φ²))``, ``φ =
        exp(−Δt/τ)``), and its mean held at 0 (the constant part is the bias's)."""
        p, J = self.priors, self.W
        phi = np.exp(-np.diff(self.knots) / p.tilt_wander_s)
        scale = p.tilt_wander_rad * np.sqrt(1 - phi**2)
        step = np.zeros((J - 1, J))
        step[np.arange(J - 1), np.arange(1, J)] = 1 / scale
        step[np.arange(J - 1), np.arange(J - 1)] = -phi / scale
        rows = np.vstack([step, np.full((1, J), 1 / (J * 1e-6))])
        return np.kron(rows, np.eye(2))

    def residuals(self, x):
        return np.concatenate([self.observation_residuals(x).ravel(), self.prior_residuals(x)])

    def jacobian(self, x):
        """Sparse Jacobian: the globals by finite differences, the walk and the features exactly (they enter the
        ground position linearly: + (1 − s)·walk[j] + s·walk[j + 1] − feature)."""
        import scipy.sparse as sp  # here, not at the top: scipy takes ~0.3 s to import, every command would pay it

        M = self.M
        base, Aw = self.observation_residuals(x, with_whitening=True)
        glob = np.zeros((2 * M, N_GLOBAL))
        for i, step in enumerate((_ANGLE_STEP, _ANGLE_STEP, _ANGLE_STEP, _DEPTH_STEP)):
            if i < 3 or self.depth_fixed is None:
                xs = x.copy()
                xs[i] += step
                glob[:, i] = ((self.observation_residuals(xs) - base) / step).ravel()
        # (M, 4): row (m, a) against columns (b = 0, 1)
        rows = np.repeat(np.arange(2 * M).reshape(M, 2), 2, axis=1)
        pairs = [
            (N_GLOBAL + 2 * self.j, Aw * (1 - self.s)[:, None, None]),
            (N_GLOBAL + 2 * (self.j + 1), Aw * self.s[:, None, None]),
            (self.first_feature + 2 * self.f, -Aw),
        ]
        if self.K:
            pairs.append((N_GLOBAL + 2 * self.J + 2 * self.k, Aw))
        if self.W:  # the wander moves each observation's tilt as the globals' tilt does, shared by its two knots
            tilt = glob.reshape(M, 2, N_GLOBAL)[:, :, :2]
            pairs.append((self.first_wander + 2 * self.j, tilt * (1 - self.s)[:, None, None]))
            pairs.append((self.first_wander + 2 * (self.j + 1), tilt * self.s[:, None, None]))
        cols = [np.tile(first[:, None] + np.array([0, 1]), 2) for first, _ in pairs]
        linear = sp.csr_matrix(
            (
                np.concatenate([d.reshape(M, 4).ravel() for _, d in pairs]),
                (np.tile(rows.ravel(), len(pairs)), np.concatenate([c.ravel() for c in cols])),
            ),
            shape=(2 * M, self.n_params),
        )
        dense = sp.hstack([sp.csr_matrix(glob), sp.csr_matrix((2 * M, self.n_params - N_GLOBAL))])
        return sp.vstack([linear + dense, self._prior_jacobian()]).tocsr()

    def _prior_jacobian(self):
        import scipy.sparse as sp

        p, J = self.priors, self.J
        n = self.n_params
        rows, cols, vals = (
            [0, 1, 2, 3],
            [0, 1, 2, 3],
            [
                1 / p.tilt_rad,
                1 / p.tilt_rad,
                1 / p.yaw_rad,
                1 / p.floor_depth_prior_m if self.depth_fixed is None else 1.0,
            ],
        )
        rate = p.walk_rate_m * np.sqrt(np.diff(self.knots))
        r = 4
        for i in range(J - 1):
            for c in range(2):
                rows += [r, r]
                cols += [N_GLOBAL + 2 * (i + 1) + c, N_GLOBAL + 2 * i + c]
                vals += [1 / rate[i], -1 / rate[i]]
                r += 1
        for c in range(2):
            rows += [r] * J
            cols += [N_GLOBAL + 2 * i + c for i in range(J)]
            vals += [1 / (J * 1e-3)] * J
            r += 1
        n_white = 2 * self.K
        if n_white:
            rows += list(range(r, r + n_white))
            cols += list(range(N_GLOBAL + 2 * J, N_GLOBAL + 2 * J + n_white))
            vals += [1 / p.white_m] * n_white
        r += n_white
        if self.W:
            wander = sp.coo_matrix(self._wander_prior_rows())
            rows += list(r + wander.row)
            cols += list(self.first_wander + wander.col)
            vals += list(wander.data)
            r += wander.shape[0]
        return sp.csr_matrix((vals, (rows, cols)), shape=(r, n))

    def start(self) -> np.ndarray:
        x = np.zeros(self.n_params)
        x[3] = self.depth0 if self.depth_fixed is None else 0.0
        x[N_GLOBAL : N_GLOBAL + 2 * self.J] = self.walk0.ravel()
        g, walk, _, _ = self.unpack(x)
        x[self.first_feature :] = self._means(self.ground(g, walk)[0]).ravel()
        return x


def _covariance(
    jac: sp.csr_matrix, n_dense: int, scale2: float, n_obs: int
) -> tuple[np.ndarray, np.ndarray]:
    """Covariance of the first ``n_dense`` parameters, the rest (2×2 feature blocks) eliminated by their Schur
    complement ``S`` of the Gauss-Newton Hessian ``H = JᵀJ``, with the first ``n_obs`` rows of ``J`` (the
    observations') of variance ``scale2`` and the priors' rows (after them, on the dense parameters only) of theirs:
    the estimate's own covariance ``H⁻¹·(scale2·H_obs + H_prior)·H⁻¹ = scale2·S⁻¹ − (scale2 − 1)·S⁻¹·H_prior·S⁻¹``
    (where the observations tell a parameter this is ``scale2·S⁻¹``; where only its prior does, the prior's
    variance). Also ``S⁻¹``: how the parameters move together in the fit (``S⁻¹``'s regressions are ``−S``'s blocks'),
    whatever the observations' variance."""
    S, _, _ = _reduced((jac.T @ jac).tocsc(), np.zeros(jac.shape[1]), n_dense)
    inv = np.linalg.inv(S)
    prior = jac[n_obs:, :n_dense]
    return scale2 * inv - (scale2 - 1.0) * inv @ (prior.T @ prior).toarray() @ inv, inv


def _per_height(prob: _Problem, x: np.ndarray, inliers: np.ndarray) -> np.ndarray:
    """How the biases at the solution ``x`` of ``prob`` move per metre of a common error of the reported heights
    (tilt_fwd, tilt_right, yaw; rad per metre reading high): the Gauss-Newton step that takes up every frame's height
    moved by the same amount, the floor's depth, the walk, the wander and the features free (the floor's depth takes
    most of it: from above, a floor point's offset shows about ``h + D/n``); the inlying observations only."""
    return _height_steps(prob, x, inliers, np.ones((prob.M, 1)))[:3, 0]


def _walk_per_height(prob: _Problem, x: np.ndarray, inliers: np.ndarray) -> np.ndarray:
    """(2J, J): how the walk's knots (north, east in turn) move (m) per metre the reported heights read high about
    each knot (linear between knots, as the walk): :func:`_per_height`'s step for a height error that varies, which
    the floor's depth and the biases cannot take up alone."""
    s = prob.s[:, None]
    hats = (np.arange(prob.J) == prob.j[:, None]) * (1 - s) + (
        np.arange(prob.J) == prob.j[:, None] + 1
    ) * s
    return _height_steps(prob, x, inliers, hats)[N_GLOBAL : N_GLOBAL + 2 * prob.J]


def _height_steps(
    prob: _Problem, x: np.ndarray, inliers: np.ndarray, shapes: np.ndarray
) -> np.ndarray:
    """The Gauss-Newton steps of the dense parameters (globals, walk, offsets, wander; the features eliminated) that
    take up the reported heights moved by each column of ``shapes`` (M, C: metres per observation), (n_dense, C)."""
    base = prob.observation_residuals(x)
    moved = copy.copy(prob)
    moved.h = prob.h + _HEIGHT_STEP
    per_m = (moved.observation_residuals(x) - base) / _HEIGHT_STEP  # (M, 2)
    jac = prob.jacobian(x)
    keep = np.concatenate([np.repeat(inliers, 2), np.ones(jac.shape[0] - 2 * prob.M)])
    jac = jac.multiply(keep[:, None]).tocsr()
    S, Hgp3, inv = _schur((jac.T @ jac).tocsc(), prob.first_feature)  # the same for every shape
    steps = []
    for shape in np.asarray(shapes, dtype=float).T:
        column = np.zeros(jac.shape[0])
        column[: 2 * prob.M] = (per_m * shape[:, None]).ravel()
        g, _ = _reduced_g(Hgp3, inv, jac.T @ (column * keep), prob.first_feature)
        steps.append(-np.linalg.solve(S, g))
    return np.array(steps).T


def height_wander_cov_m2(priors: Priors, knots_s: np.ndarray) -> np.ndarray:
    """(J, J) the reported heights' wander at the knots about its mean over them (m²): a first-order Gauss-Markov
    process of :attr:`Priors.height_wander_m`, ``height_wander_s``; its mean is a common error, which the floor's depth
    and the tilt take up (:attr:`BottomEstimate.bias_per_height_rad`), not the walk (whose mean is held at 0)."""
    t = np.asarray(knots_s, dtype=float)
    cov = priors.height_wander_m**2 * np.exp(-np.abs(t[:, None] - t) / priors.height_wander_s)
    centre = np.eye(len(t)) - 1.0 / len(t)
    return centre @ cov @ centre


def _reduced(H: sp.csc_matrix, g: np.ndarray, n_dense: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The normal equations ``H·δ = −g`` with the parameters after the first ``n_dense`` (2×2 feature blocks, none
    coupled to another) eliminated: the Schur complement ``S`` (n_dense × n_dense), the reduced ``g`` and
    ``g_fᵀ·H_ff⁻¹·g_f`` (what the features' own step takes off the squared residuals)."""
    S, Hgp3, inv = _schur(H, n_dense)
    return (S, *_reduced_g(Hgp3, inv, g, n_dense))


def _schur(H: sp.csc_matrix, n_dense: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_reduced`'s Schur complement ``S``, with what reduces a ``g`` (:func:`_reduced_g`): the dense-feature
    block (n_dense, nf, 2) and the features' inverted 2×2 blocks (nf, 2, 2)."""
    Hgg = H[:n_dense, :n_dense].toarray()
    Hgp = H[:n_dense, n_dense:].toarray()
    Hpp = H[n_dense:, n_dense:]
    nf = Hpp.shape[0] // 2
    blocks = np.zeros((nf, 2, 2))
    for a in range(2):
        for b in range(2):
            blocks[:, a, b] = Hpp[a::2, :][:, b::2].diagonal()
    blocks += np.eye(2) * 1e-12
    inv = np.linalg.inv(blocks)
    Hgp3 = Hgp.reshape(n_dense, nf, 2)
    return Hgg - np.einsum("gfa,fab,hfb->gh", Hgp3, inv, Hgp3), Hgp3, inv


def _reduced_g(
    Hgp3: np.ndarray, inv: np.ndarray, g: np.ndarray, n_dense: int
) -> tuple[np.ndarray, float]:
    """:func:`_reduced`'s reduced ``g`` and ``g_fᵀ·H_ff⁻¹·g_f``, from :func:`_schur`'s blocks."""
    gp = g[n_dense:].reshape(len(inv), 2)
    inv_gp = np.einsum("fab,fb->fa", inv, gp)
    return g[:n_dense] - np.einsum("gfa,fa->g", Hgp3, inv_gp), float(np.sum(gp * inv_gp))


def walk_rate_log_evidence(prob: _Problem, x: np.ndarray, rates_m) -> tuple[np.ndarray, np.ndarray]:
    """The log marginal likelihood (up to a constant) of each walk rate ``rates_m`` (m/√s) for the recording of
    ``prob``, linearized at its solution ``x`` (the walk, the frames' offsets and the features enter the residuals
    linearly; the biases and the depth, nearly so): the residuals' Gaussian integral over all the parameters,
    ``−½·χ²_min − ½·log det S − n·log rate``, with ``S`` the walk's, the offsets' and the globals' posterior
    information (the features eliminated, whose information does not depend on the rate) and ``n`` the walk's
    increments (their prior's normalisation). The observations are weighted as the robust loss weighs them at ``x``
    and scaled by their own variance there (the pixel sigma is a prior's guess). A rate too small bends the floor to
    fit the velocity's steps; one too large pays for the freedom it does not use. Also each rate's walk (R, J, 2) in
    the same linear model (the step from ``x``'s)."""
    import scipy.sparse as sp

    M2, p = 2 * prob.M, prob.priors
    r, jac = prob.residuals(x), prob.jacobian(x)
    w = np.ones(len(r))
    w[:M2] = (1.0 + (r[:M2] / p.loss_scale) ** 2) ** -0.25  # √ρ' of soft_l1: the loss's weights
    dof = max(1, M2 - prob.n_params)
    w[:M2] /= np.sqrt(np.sum((w[:M2] * r[:M2]) ** 2) / dof)
    walk_rows = np.zeros(len(r), bool)
    walk_rows[M2 + N_GLOBAL : M2 + N_GLOBAL + 2 * (prob.J - 1)] = True
    fixed = sp.diags(np.where(walk_rows, 0.0, w)) @ jac
    walk = sp.diags(walk_rows.astype(float)) @ jac
    b_fixed, b_walk = np.where(walk_rows, 0.0, w * r), np.where(walk_rows, r, 0.0)
    n = prob.first_feature
    S0, g0, taken = _reduced((fixed.T @ fixed).tocsc(), fixed.T @ b_fixed, n)
    Sw = (walk.T @ walk)[:n, :n].toarray()
    gw = (walk.T @ b_walk)[:n]
    c0 = float(b_fixed @ b_fixed) - taken
    cw = float(b_walk @ b_walk)
    out, walks = [], []
    for rate in np.asarray(rates_m, dtype=float):
        k = (p.walk_rate_m / rate) ** 2  # the walk's rows were made at the priors' rate
        S, g = S0 + k * Sw, g0 + k * gw
        step = -np.linalg.solve(S, g)
        chi2 = c0 + k * cw + g @ step
        out.append(-0.5 * chi2 - 0.5 * np.linalg.slogdet(S)[1] - walk_rows.sum() * np.log(rate))
        walks.append((x + np.pad(step, (0, len(x) - n)))[N_GLOBAL : N_GLOBAL + 2 * prob.J])
    return np.array(out), np.array(walks).reshape(len(out), prob.J, 2)


def estimate(
    camera: Camera,
    n_water,
    poses: FramePoses,
    obs: Observations,
    priors: Priors = Priors(),
    parts: int = 0,
) -> BottomEstimate:
    """The pose biases, floor depth, features and position walk from bottom feature tracks (see the module doc).

    ``obs.feature`` numbers features 0..F-1 (each seen in ≥ 2 frames to say anything); ``n_water`` None: straight rays.
    ``parts`` ≥ 2: also solved on that many consecutive stretches of time alone, and the sigmas widened by their
    spread (:func:`with_parts`).
    """
    est = _estimate(camera, n_water, poses, obs, priors, per_height=True)
    return est if parts < 2 else with_parts(est, camera, n_water, poses, obs, parts)


def with_parts(
    est: BottomEstimate, camera: Camera, n_water, poses: FramePoses, obs: Observations, parts: int
) -> BottomEstimate:
    """``est`` with each of ``parts`` consecutive stretches of the frames' times solved alone (:attr:`BottomEstimate.parts`)
    and its sigmas widened by the standard error of their mean (their sample standard deviation over the square root
    of their number, see the module doc), the biases' also by the whole fit's distance from their mean where more than
    :data:`WHOLE_APART` times the two sigmas together; with fewer than two parts solved, by the priors (the recording
    does not show that the bottom told the biases)."""
    t = np.asarray(poses.t_s, dtype=float)
    edges = np.linspace(t.min(), t.max(), parts + 1)
    part = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, parts - 1)
    values = np.array(
        [
            _part_values(camera, n_water, poses, obs, est.priors, np.flatnonzero(part == i))
            for i in range(parts)
        ]
    )
    solved = values[np.all(np.isfinite(values), axis=1)]
    p = est.priors
    if len(solved) >= 2:
        spread = np.std(solved, axis=0, ddof=1) / np.sqrt(len(solved))
        # the whole fit's biases outside their parts (a bias that steps, absorbed by another): that distance is claimed
        away = np.abs(np.array([*est.tilt_rad, est.yaw_rad]) - solved[:, :3].mean(axis=0))
        apart = away > WHOLE_APART * np.hypot(spread[:3], np.sqrt(np.diagonal(est.cov_bias)))
        spread[:3] = np.where(apart, np.hypot(spread[:3], away), spread[:3])
    else:
        spread = np.array([p.tilt_rad, p.tilt_rad, p.yaw_rad, p.floor_depth_prior_m])
    sigma_depth = (
        0.0 if p.floor_depth_m is not None else float(np.hypot(est.sigma_floor_depth_m, spread[3]))
    )
    return replace(
        est.with_walk_error(est.walk_per_bias_m * spread[:3]),
        cov_bias=est.cov_bias + np.diag(spread[:3] ** 2),
        sigma_floor_depth_m=sigma_depth,
        parts=values,
    )


def _part_values(
    camera: Camera,
    n_water,
    poses: FramePoses,
    obs: Observations,
    priors: Priors,
    frames: np.ndarray,
) -> np.ndarray:
    """tilt_fwd, tilt_right, yaw, floor depth (4,) solved from ``frames`` (indices into ``poses``) alone; NaN with
    fewer than :data:`MIN_PART_FEATURES` features seen in two of them."""
    index = np.full(len(poses.t_s), -1)
    index[frames] = np.arange(len(frames))
    keep = index[np.asarray(obs.frame, dtype=int)] >= 0
    feature = np.asarray(obs.feature, dtype=int)[keep]
    frame = index[np.asarray(obs.frame, dtype=int)[keep]]
    seen = np.zeros((int(feature.max()) + 1 if len(feature) else 0, len(frames)), bool)
    seen[feature, frame] = True
    twice = seen.sum(axis=1)[feature] >= 2 if len(feature) else keep[:0]
    if len(frames) < 3 or len(np.unique(feature[twice])) < MIN_PART_FEATURES:
        return np.full(N_GLOBAL, np.nan)
    _, renumbered = np.unique(feature[twice], return_inverse=True)
    sub = Observations(
        frame[twice],
        renumbered,
        np.asarray(obs.u, float)[keep][twice],
        np.asarray(obs.v, float)[keep][twice],
    )
    take = FramePoses(
        *(
            None if a is None else np.asarray(a)[frames]
            for a in (
                poses.t_s,
                poses.R_ned_from_cv,
                poses.camera_ne_m,
                poses.height_m,
                poses.bias_heading_rad,
                poses.velocity_ne_mps,
                poses.velocity_origin_ne_m,
            )
        )
    )
    e = _estimate(camera, n_water, take, sub, priors)
    return np.array([*e.tilt_rad, e.yaw_rad, e.floor_depth_m])


def _estimate(
    camera: Camera,
    n_water,
    poses: FramePoses,
    obs: Observations,
    priors: Priors,
    per_height: bool = False,
) -> BottomEstimate:
    """The whole recording's fit (:func:`estimate` without parts); ``per_height``: with
    :attr:`BottomEstimate.bias_per_height_rad` (else zeros)."""
    import scipy.sparse as sp

    prob = _Problem(camera, n_water, poses, obs, priors)
    fit = _solve(prob, prob.start())
    evidence, rate_spread = np.zeros((0, 2)), 0.0
    if priors.walk_rates_m:
        rates = np.asarray(priors.walk_rates_m, dtype=float)
        log_evidence, walks = walk_rate_log_evidence(prob, fit.x, rates)
        evidence, best = np.column_stack([rates, log_evidence]), int(np.argmax(log_evidence))
        rate_spread = _rate_spread(log_evidence, walks, best)
        chosen = replace(priors, walk_rate_m=float(rates[best]), walk_rates_m=())
        prob = _Problem(camera, n_water, poses, obs, chosen)
        fit, priors = _solve(prob, fit.x), chosen
    x = fit.x
    r_obs = prob.observation_residuals(x)
    norm = np.hypot(r_obs[:, 0], r_obs[:, 1])
    inliers = norm < 3.0 * priors.loss_scale
    n_dense = prob.first_feature
    dof = max(1, 2 * int(inliers.sum()) - prob.n_params + 4)
    # the observations' variance factor: the residuals' own (the pixel sigma is a prior's guess), not floored
    scale2 = float(np.sum(norm[inliers] ** 2) / dof)
    cov, together = _covariance(sp.csr_matrix(fit.jac), n_dense, scale2, 2 * prob.M)
    g, walk, _, feats = prob.unpack(x)
    cov_walk_m2 = (
        cov[N_GLOBAL : N_GLOBAL + 2 * prob.J, N_GLOBAL : N_GLOBAL + 2 * prob.J] + rate_spread
    )
    if per_height and priors.height_wander_m > 0:
        moves = _walk_per_height(prob, x, inliers)
        cov_walk_m2 = cov_walk_m2 + moves @ height_wander_cov_m2(priors, prob.knots) @ moves.T
    return BottomEstimate(
        tilt_rad=g[:2].copy(),
        yaw_rad=float(g[2]),
        cov_bias=cov[:3, :3].copy(),
        floor_depth_m=float(g[3]),
        sigma_floor_depth_m=0.0 if priors.floor_depth_m is not None else float(np.sqrt(cov[3, 3])),
        knot_t_s=prob.knots,
        walk_ne_m=walk.copy(),
        sigma_walk_ne_m=np.sqrt(np.diagonal(cov_walk_m2)).reshape(prob.J, 2),
        cov_walk_m2=cov_walk_m2,
        features_ne_m=feats.copy(),
        rms_px=float(np.sqrt(np.mean(norm[inliers] ** 2) / 2) * priors.pixel_px),
        slide_share=slide_share(camera, obs),
        n_observations=prob.M,
        n_features=prob.F,
        n_frames=len(np.unique(prob.k)),
        inliers=inliers,
        priors=priors,
        walk_rate_evidence=evidence,
        tilt_wander_rad=prob.wander(x).copy(),
        velocity_walk_ne_m=prob.walk0.copy()
        if poses.velocity_ne_mps is not None
        else np.zeros((0, 2)),
        bias_per_height_rad=_per_height(prob, x, inliers) if per_height else np.zeros(3),
        walk_per_bias_m=together[N_GLOBAL : N_GLOBAL + 2 * prob.J, :3]
        @ np.linalg.inv(together[:3, :3]),
    )


def _rate_spread(log_evidence: np.ndarray, walks: np.ndarray, best: int) -> np.ndarray:
    """The walk's covariance (2J × 2J, m²) for not knowing its rate: the walks of the rates tried (R, J, 2) about the
    chosen one's, weighted by their marginal likelihoods (the rates tried taken alike a priori). Rates the recording
    cannot tell apart but whose walks differ widen the walk's sigma (as the parts' spread widens the biases')."""
    weight = np.exp(log_evidence - log_evidence.max())
    d = (walks - walks[best]).reshape(len(walks), -1)
    return np.einsum("r,ra,rb->ab", weight / weight.sum(), d, d)


def _solve(prob: _Problem, x0: np.ndarray):
    """The robust least-squares solution of ``prob`` from ``x0`` (:func:`scipy.optimize.least_squares`'s result)."""
    from scipy.optimize import least_squares

    return least_squares(
        prob.residuals,
        x0,
        jac=prob.jacobian,
        loss="soft_l1",
        f_scale=prob.priors.loss_scale,
        x_scale="jac",
        method="trf",
        tr_solver="lsmr",
        max_nfev=60,
    )
