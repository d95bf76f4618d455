"""Per-pixel ray casting of the underwater scene as the UAV's camera sees it.

Each pixel's ray comes from OpenCV's undistortion (:func:`~sim_fixtures.geometry.pixel_rays`,
so the image carries the lens distortion), is turned into NED by the camera's true
attitude, bent at the flat surface by Snell's law in vector form
(:func:`~sim_fixtures.geometry.refract_into_water`), and followed to the seafloor (a world-fixed texture) or to the UUV, a box of the
BlueROV2's size whose reference point is the centre of its top face. Light is
attenuated along the water path per colour channel; caustics move over the
floor; the surface reflects the sky (Schlick's Fresnel) and, optionally, the sun.
The UUV is ray cast only in a window around it, with supersampling.

Look-alikes (``[second_uuv]``, ``[rock]``) are boxes too, ray cast in windows of their own:
each ray takes the nearest box it meets. With ``[render] shadow`` > 0 the boxes cast
shadows: a point on the floor or on a box is in shadow where the ray from it towards the
sun (the sunlight refracted at the flat surface, straight in the water) meets another box;
there the sun's share of the light (and the caustics, which are sunlight) is missing. A buoy (``[buoy]``) is a box
too; with its deck at the surface it floats: its top is seen straight through the air, sunlit, before anything in
the water (:meth:`Renderer._deck`).

With wind waves (``[waves]``, :mod:`sim_fixtures.waves`) every ray meets the wavy surface
(:func:`water_path_ned`: its height included) and is refracted through the local facet's
normal; Fresnel's reflectance and the sky are the facet's, and the sun's glint is the sun
reflected by the facet, widened by the unresolved waves' slopes. The caustic pattern drifts
with the waves that focus it, lights the vehicles too, and fades with depth
(``[waves] caustic_fade_per_m``). ``[site] turbidity_per_m`` veils the line of sight.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import cv2
import numpy as np

from . import texture
from .buoy import albedo as buoy_albedo
from .geometry import SimCamera, facet_normal_up, pixel_rays, refract_into_water
from .marker import paint
from .scenario import Scenario
from .waves import downwind_rad, phase_speed, wave_field

FLOOR_M_PER_PX = 0.015
SKY_BGR = np.array([235.0, 215.0, 200.0], np.float32)
# the smooth part of the sun's glint; the rest comes in sparkles from surface ripples
GLINT_HAZE = 0.1
MIN_CONTRAST = 1.0  # grey levels: the UUV counts as visible only if it changes its box at least this much (RMS)
GREY_BGR = np.array([0.114, 0.587, 0.299])  # luma weights (as cv2.COLOR_BGR2GRAY)


@dataclass(frozen=True)
class Box:
    """A box in the water, level: its body frame has the origin at the centre of its top face, x forward (along
    ``heading``, radians from North), y right, z down; it spans x∈±L/2, y∈±W/2, z∈[0, H]."""

    ned: np.ndarray  # (3,) centre of its top face, world NED
    heading: float
    size_m: tuple  # length, width, height
    look: str  # "vehicle" (a BlueROV2), "rock" or "buoy" (sim_fixtures.buoy)


@dataclass(frozen=True)
class View:
    """The true geometry of one frame (world NED, metres, radians)."""

    R_ned_from_cv: np.ndarray  # (3, 3)
    camera_ned: np.ndarray  # (3,)
    uuv_ned: np.ndarray  # (3,) centre of the UUV's top face
    uuv_heading: float
    uuv_visible: bool
    tau_s: float
    others: tuple = ()  # Boxes of the look-alikes at this frame (the second vehicle, the rock)


class WaterPath(NamedTuple):
    """Where camera rays (N) cross the water surface and how they go on in the water (world NED)."""

    surface_ne: np.ndarray  # (N, 2) the crossing's north and east
    down_m: np.ndarray  # (N,) its down coordinate: 0 on the flat surface, −η on a wave
    dir_water: np.ndarray  # (N, 3) unit direction in the water
    wet: np.ndarray  # (N,) False for rays that do not point down into the water (their other values are meaningless)
    # (N, 3) the facets' unit normals on the air side; None: the flat surface
    normal_up: np.ndarray | None


CROSSING_ITERATIONS = 2  # fixed-point steps from the flat crossing to a wave's (the error shrinks by slope·tan θ each)


def water_path(ray_cv, view: View, n_water: float, surface=None) -> WaterPath:
    """:func:`water_path_ned` of rays ``ray_cv`` (N, 3) in the camera frame of a view."""
    return water_path_ned(
        ray_cv @ view.R_ned_from_cv.T.astype(ray_cv.dtype), view.camera_ned, n_water, surface
    )


def water_path_ned(d, camera_ned, n_water: float, surface=None) -> WaterPath:
    """Where rays ``d`` (N, 3, NED unit) from a camera in the air (``camera_ned`` (3,), or (N, 3): one per ray) cross
    the water surface and how they continue.

    ``surface``: the waves at the frame's time (:class:`~sim_fixtures.waves.ExactSurface` or ``GriddedSurface``), or
    None for the flat surface down = 0. On waves the crossing with down = −η(north, east) is found by fixed-point
    steps from the flat crossing, r ← (h − η(c + r·d_ne))/d_down for the ray's length to the surface's height, and the
    ray is refracted through the facet's normal there (Snell, :func:`~sim_fixtures.geometry.refract_into_water`).
    """
    wet = d[:, 2] > 1e-3
    d = np.where(wet[:, None], d, np.array([0.0, 0.0, 1.0], d.dtype))
    camera_ned = np.asarray(camera_ned)
    height = -camera_ned[..., 2]
    flat = camera_ned[..., :2].astype(d.dtype) + d[:, :2] * (height / d[:, 2])[:, None]
    if surface is None:
        return WaterPath(
            flat,
            np.zeros(len(d), d.dtype),
            refract_into_water(d, n_water).astype(d.dtype),
            wet,
            None,
        )
    ne, camera_ned, height = flat, camera_ned.astype(d.dtype), height.astype(d.dtype)
    for _ in range(CROSSING_ITERATIONS):
        reach = (height - surface.height(ne)) / d[:, 2]
        ne = camera_ned[..., :2] + d[:, :2] * reach[:, None]
    normal = facet_normal_up(surface.gradient(ne).astype(d.dtype, copy=False))
    t = refract_into_water(d, n_water, normal)
    wet &= np.isfinite(t[:, 0])
    t[~wet] = (0.0, 0.0, 1.0)
    return WaterPath(ne, camera_ned[..., 2] + reach * d[:, 2], t, wet, normal)


def to_body(surface_ne, dir_water, box: Box, depth_m=0.0):
    """Ray origins and directions (N, 3) in a box's body frame (see :class:`Box`).

    ``surface_ne`` (N, 2) the origins' north and east, at ``depth_m`` (a scalar or (N,); 0: on the surface).
    """
    c, s = np.cos(box.heading), np.sin(box.heading)
    dn = surface_ne[:, 0] - box.ned[0]
    de = surface_ne[:, 1] - box.ned[1]
    z = (
        np.full_like(dn, -box.ned[2])
        if np.isscalar(depth_m) and depth_m == 0.0
        else depth_m - box.ned[2]
    )
    origin = np.stack([c * dn + s * de, -s * dn + c * de, z], axis=-1)
    direction = np.stack(
        [
            c * dir_water[:, 0] + s * dir_water[:, 1],
            -s * dir_water[:, 0] + c * dir_water[:, 1],
            dir_water[:, 2],
        ],
        axis=-1,
    )
    return origin, direction


def hit_box(origin, direction, size_m):
    """Slab test against the box x∈±L/2, y∈±W/2, z∈[0, H]: ``(hit, t_m, face_axis, point)``."""
    L, W, H = size_m
    lo = np.array([-L / 2, -W / 2, 0.0])
    hi = np.array([L / 2, W / 2, H])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - origin) / direction
        t2 = (hi - origin) / direction
    t_near = np.minimum(t1, t2)
    t_near = np.where(np.isnan(t_near), -np.inf, t_near)
    t_far = np.maximum(t1, t2)
    t_far = np.where(np.isnan(t_far), np.inf, t_far)
    t_in = t_near.max(axis=1)
    hit = (t_in <= t_far.min(axis=1)) & (
        t_in >= 0
    )  # 0: a top face at the surface, where the rays enter
    return hit, t_in, t_near.argmax(axis=1), origin + t_in[:, None] * direction


def uuv_albedo(point, face_axis):
    """Stylised BlueROV2 seen from above: dark frame, light electronics tube, four thruster guards (BGR)."""
    x, y = point[:, 0], point[:, 1]
    col = np.tile(np.array([38.0, 36.0, 34.0]), (len(x), 1))
    col[np.abs(y) > 0.12] = (70.0, 62.0, 55.0)  # buoyancy blocks along the sides
    for sx in (-1, 1):
        for sy in (-1, 1):
            col[np.hypot(x - sx * 0.16, y - sy * 0.115) < 0.05] = (160.0, 105.0, 40.0)
    col[(np.abs(y) < 0.055) & (np.abs(x) < 0.18)] = (200.0, 200.0, 190.0)  # acrylic tube
    col[(np.abs(y) < 0.03) & (x > 0.16) & (x < 0.2)] = (
        40.0,
        200.0,
        235.0,
    )  # yellow dome rim, the nose
    shade = np.where(face_axis == 2, 1.0, 0.55)
    return col * shade[:, None]


def rock_albedo(point, face_axis):
    """A dark, mottled rock (BGR): the sand's darkest pebbles' colour, blotched."""
    x, y = point[:, 0], point[:, 1]
    mottle = (
        1.0 + 0.25 * np.sin(37.0 * x + 1.3) * np.sin(29.0 * y + 0.4) + 0.12 * np.sin(61.0 * (x + y))
    )
    col = np.array([40.0, 47.0, 46.0]) * mottle[:, None]
    return col * np.where(face_axis == 2, 1.0, 0.55)[:, None]


ALBEDO = {"vehicle": uuv_albedo, "rock": rock_albedo}


def floats(box: Box) -> bool:
    """A buoy whose deck is at the surface (depth 0): seen straight through the air, not through the water."""
    return box.look == "buoy" and box.ned[2] <= 0.0


def pixels_of(windows, height: int, width: int):
    """Rows and columns (row-major) of the pixels in the union of windows ``(v0, v1, u0, u1)``."""
    mask = np.zeros((height, width), bool)
    for v0, v1, u0, u1 in windows:
        mask[v0:v1, u0:u1] = True
    return np.nonzero(mask)


def subsamples(rows, cols, ss: int, scale: int = 1):
    """Image coordinates (u, v), each (P, ss, ss), of ss x ss rays spread over pixels (rows, cols) of an image
    ``scale`` times coarser than the camera's (its pixel i centred on camera pixel scale·i + (scale − 1)/2)."""
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    if scale == 1:
        u, v = cols[:, None, None] + sub[None, None, :], rows[:, None, None] + sub[None, :, None]
    else:
        centre = (scale - 1) / 2
        u = scale * cols[:, None, None] + centre + scale * sub[None, None, :]
        v = scale * rows[:, None, None] + centre + scale * sub[None, :, None]
    return np.broadcast_arrays(u, v)


RAY_TILE = 32  # pixels a side of the tiles the UUV's rays are cached in (Renderer._rays) ...
RAY_TILES_KEPT = 512  # ... and how many are kept (at supersample 2: 100 kB each)
NOISE_MARGIN = 64  # the noise field is this much larger than a frame: each frame's noise is cut from it at an offset


def noise_rng(sc: Scenario) -> np.random.Generator:
    """The generator of the frames' noise offsets (see :meth:`Renderer.render_seen`)."""
    return np.random.default_rng([sc.seed, 303])


def _noise_offset(rng: np.random.Generator) -> tuple[int, int]:
    dy, dx = rng.integers(0, NOISE_MARGIN, 2)
    return int(dy), int(dx)


def noise_offsets(sc: Scenario, n: int) -> list[tuple[int, int]]:
    """The noise offsets of frames 0 … n − 1 as a renderer rendering them in turn draws them."""
    rng = noise_rng(sc)
    return [_noise_offset(rng) for _ in range(n)]


def floor_div(camera: SimCamera) -> int:
    """How many image pixels a side one floor pixel is (see :class:`Renderer`)."""
    return 2 if camera.width >= 1200 and camera.width % 2 == camera.height % 2 == 0 else 1


CAUSTIC_DRIFT_NE = (
    (0.11, 0.07),
    (-0.05, 0.13),
)  # m/s: the two caustic layers' drift over a flat surface
# the caustic pattern's cells (0.12-1 m) are focused by waves about this long ...
CAUSTIC_WAVELENGTH_M = 0.4
CAUSTIC_SPREAD_DEG = 30.0  # ... that travel downwind, ± this


def wave_caustic_drift_ne(sc: Scenario) -> tuple:
    """The caustic layers' drift (m/s, north and east) under waves: at the phase speed of the waves that focus them,
    downwind ± ``CAUSTIC_SPREAD_DEG``."""
    downwind = downwind_rad(sc)
    speed = float(phase_speed(2 * np.pi / CAUSTIC_WAVELENGTH_M))
    return tuple(
        (speed * np.cos(downwind + a), speed * np.sin(downwind + a))
        for a in np.radians([CAUSTIC_SPREAD_DEG, -CAUSTIC_SPREAD_DEG])
    )


class Renderer:
    """Renders frames of one scenario; textures and rays are made once.

    The floor's smooth terms (texture coordinates, attenuation, Fresnel, glint) are
    computed exactly on a grid every ``COARSE`` floor pixels and interpolated
    bilinearly (the mapping is smooth, so this is exact to far below a pixel). The
    floor is looked up at the image's resolution divided by ``floor_div`` (2 for even
    sizes from 1200 px wide: the 1.5 cm texture has no finer detail at usual heights) and
    scaled up; the UUV is always ray cast per image pixel, supersampled.

    With waves (``[waves]``) the mapping is not smooth: the floor's rays are cast per floor
    pixel (``coarse`` 1), through the waves sampled on a grid for the frame
    (:meth:`~sim_fixtures.waves.WaveField.gridded`); the vehicles' rays through the exact
    sums of the waves (:class:`~sim_fixtures.waves.ExactSurface`), as the truth's pixel is found.
    """

    COARSE = 4

    def __init__(self, sc: Scenario, camera: SimCamera):
        self.sc = sc
        self.camera = camera
        rng = np.random.default_rng([sc.seed, 202])
        self.n_water = sc.site.refractive_index
        self.atten = np.asarray(sc.site.attenuation_bgr_per_m, np.float32)
        self.water_bgr = np.asarray(sc.site.water_bgr, np.float32)
        self.floor_div = div = floor_div(camera)
        self.waves = wave_field(sc, camera.fx / div)
        self.coarse = c = self.COARSE if self.waves is None else 1
        self.floor_w, self.floor_h = -(-camera.width // div), -(-camera.height // div)
        self.grid_w, self.grid_h = -(-self.floor_w // c) + 2, -(-self.floor_h // c) + 2
        v, u = np.mgrid[0 : self.grid_h, 0 : self.grid_w].astype(np.float64)
        # grid point j sits at floor pixel c*(j-1) + (c-1)/2, so cv2.resize by c lands on floor pixel
        # centres (offset c); floor pixel i is centred on image pixel div*i + (div-1)/2
        fu, fv = c * (u - 1) + (c - 1) / 2, c * (v - 1) + (c - 1) / 2
        self.grid_rays = pixel_rays(
            camera, div * fu + (div - 1) / 2, div * fv + (div - 1) / 2
        ).reshape(-1, 3)
        if (
            self.waves is not None
        ):  # a ray per floor pixel: float32 is plenty (micrometres at tens of metres)
            self.grid_rays = self.grid_rays.astype(np.float32)
            edge = np.zeros((self.grid_h, self.grid_w), bool)
            edge[[0, -1], :] = edge[:, [0, -1]] = True
            self.edge_rays = self.grid_rays[edge.ravel()].astype(float)
        self.floor = texture.seafloor(rng, m_per_px=FLOOR_M_PER_PX)
        paint(self.floor, sc, FLOOR_M_PER_PX)
        self.caustics = (texture.caustics(rng), texture.caustics(rng))
        self.caustic_drift_ne = (
            CAUSTIC_DRIFT_NE if self.waves is None else wave_caustic_drift_ne(sc)
        )
        still = self._caustic_texture(0.0)
        self.caustic_mean, self.caustic_std = float(still.mean()), float(still.std())
        self.sparkle = np.clip(texture.fractal_noise(rng, 512, 0.6) - 1.5, 0.0, None)
        margin = NOISE_MARGIN
        self.noise = (
            rng.standard_normal((camera.height + margin, camera.width + margin, 3))
            * sc.render.noise_sigma
        ).astype(np.float32)
        self.noise_rng = noise_rng(sc)
        el, az = np.radians(sc.render.sun_elevation_deg), np.radians(sc.render.sun_azimuth_deg)
        self.sun_up_ned = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
        self.shadow = sc.render.shadow if sc.render.sun_elevation_deg > 0 else 0.0
        # going down, unit
        self.sunlight_in_water = refract_into_water(-self.sun_up_ned, self.n_water)
        self._ray_tiles: OrderedDict[int, np.ndarray] = OrderedDict()  # see _rays

    # --- geometry shared with the tests ------------------------------------------------------------
    def uuv_box(self, view: View) -> Box:
        return Box(view.uuv_ned, view.uuv_heading, self.sc.uuv.size_m, "vehicle")

    def exact_surface(self, view: View):
        """The waves at the view's time as the vehicles' rays meet them (None: the flat surface)."""
        return None if self.waves is None else self.waves.at(view.tau_s)

    def body_rays(self, u, v, view: View):
        """The UUV's body-frame origins and directions of the rays through distorted pixels (u, v)."""
        ray = pixel_rays(self.camera, np.ravel(u), np.ravel(v))
        p = water_path(ray, view, self.n_water, self.exact_surface(view))
        origin, direction = to_body(p.surface_ne, p.dir_water, self.uuv_box(view), p.down_m)
        origin[~p.wet] = np.nan
        return origin, direction, ray

    def top_face_xy(self, u, v, view: View):
        """Body (x, y) where the rays of pixels (u, v) meet the top face's plane, (N, 2)."""
        origin, direction, _ = self.body_rays(u, v, view)
        t = -origin[:, 2] / direction[:, 2]
        return origin[:, :2] + t[:, None] * direction[:, :2]

    # --- light ---------------------------------------------------------------------------------------
    def _through_water(self, light_depth_m, path_m):
        """``(gain, veil)``: seen colour = albedo·gain + veil for a surface at ``light_depth_m``
        seen through ``path_m`` of water (per BGR channel, arrays (N, 3)); ``[site] turbidity_per_m`` attenuates
        the line of sight too."""
        a = self.atten
        trans = np.exp(-(a + self.sc.site.turbidity_per_m) * path_m[:, None])
        return self.sc.render.exposure * np.exp(
            -a * light_depth_m[:, None]
        ) * trans, self.water_bgr * (1.0 - trans)

    def _surface(self, ray_cv, view: View, normal_up=None):
        """``(keep, add)`` of the water surface for camera rays: seen = underwater·keep + add.

        ``keep`` is 1 − Fresnel reflectance (Schlick) (N, 1); ``add`` the reflected sky
        plus the smooth part of the sun's glint (N, 3). On waves (``normal_up`` (N, 3), the
        facets' normals) both at each ray's facet, and the glint is the sun reflected by it:
        the shorter, unresolved waves' slopes (Gaussian, mean square ``unresolved_mss``) turn
        the reflection by twice theirs, so its brightness falls as exp(−θ²/(4·mss)), θ the angle
        from the reflected ray to the sun (θ² ≈ 2·(1 − cos θ)).
        """
        d = ray_cv @ view.R_ned_from_cv.T.astype(ray_cv.dtype)
        if normal_up is None:
            cos_i = np.clip(d[:, 2], 0.0, 1.0)
        else:
            cos_i = np.clip(-np.sum(d * normal_up, axis=1), 0.0, 1.0)
        n = self.n_water
        f0 = ((n - 1) / (n + 1)) ** 2
        fresnel = (f0 + (1 - f0) * (1 - cos_i) ** 5)[:, None]
        add = SKY_BGR * fresnel
        if self.sc.render.glint > 0 and normal_up is None:
            align = (d * np.array([1.0, 1.0, -1.0])) @ self.sun_up_ned
            add = (
                add
                + (GLINT_HAZE * self.sc.render.glint * 255.0 * np.exp((align - 1.0) / 0.02))[
                    :, None
                ]
            )
        elif self.sc.render.glint > 0:
            align = (d + 2 * cos_i[:, None] * normal_up) @ self.sun_up_ned
            glint = np.exp((align - 1.0) / (2 * self.waves.unresolved_mss))
            add = add + (self.sc.render.glint * 255.0 * glint)[:, None]
        return 1.0 - fresnel, add

    # --- image ---------------------------------------------------------------------------------------
    def floor_surface(self, view: View):
        """The waves at the view's time on a grid under the floor's rays (:meth:`~sim_fixtures.waves.WaveField.gridded`,
        reaching 5 σ of η times the steepest ray's tan θ past their flat crossings), or None for the flat surface."""
        if self.waves is None:
            return None
        d = self.edge_rays @ view.R_ned_from_cv.T  # the farthest crossings are the image's edges'
        d = d[d[:, 2] > 1e-3]
        if len(d) == 0:
            return None
        ne = view.camera_ned[:2] + d[:, :2] * (-view.camera_ned[2] / d[:, 2])[:, None]
        reach = self.waves.grid_reach_m * np.max(np.hypot(d[:, 0], d[:, 1]) / d[:, 2])
        return self.waves.gridded(ne.min(axis=0) - reach, ne.max(axis=0) + reach, view.tau_s)

    def _coarse(self, view: View, boxes, floor_waves):
        """Floor-resolution smooth fields from the coarse grid (dict of float32 arrays), per box the
        grid points whose rays pass near it, and per box the grid points whose floor its shadow may reach.
        ``floor_waves``: :meth:`floor_surface`'s."""
        p = water_path(self.grid_rays, view, self.n_water, floor_waves)
        surface, dir_water, wet = p.surface_ne, p.dir_water, p.wet
        depth = self.sc.site.floor_depth_m
        t = (depth - p.down_m) / dir_water[:, 2]
        fn = surface[:, 0] + dir_water[:, 0] * t
        fe = surface[:, 1] + dir_water[:, 1] * t
        gain, veil = self._through_water(np.full(len(t), depth), t)
        keep, add = self._surface(self.grid_rays, view, p.normal_up)
        gain = np.where(wet[:, None], gain * keep, 0.0)
        veil = np.where(wet[:, None], veil * keep + add, SKY_BGR)
        fields = {"map": np.stack([fe, -fn], axis=-1) / FLOOR_M_PER_PX, "gain": gain, "veil": veil}
        if self.sc.render.glint > 0 and self.waves is None:
            fields["sparkle_map"] = np.stack([surface[:, 1], -surface[:, 0]], axis=-1) / 0.01
            fields["glint"] = (add - SKY_BGR * (1 - keep))[:, :1] / GLINT_HAZE  # grey: any channel
        c = self.coarse
        out = {}
        for key, f in fields.items():
            grid = f.reshape(self.grid_h, self.grid_w, -1).astype(np.float32)
            full = cv2.resize(
                grid, (self.grid_w * c, self.grid_h * c), interpolation=cv2.INTER_LINEAR
            )
            out[key] = full.reshape(self.grid_h * c, self.grid_w * c, -1)[
                c : c + self.floor_h, c : c + self.floor_w
            ]
        grid = (self.grid_h, self.grid_w)
        near = [self._near(p, b).reshape(grid) for b in boxes]
        shade = (
            [self._shade_near(fn, fe, wet, b).reshape(grid) for b in boxes]
            if self.shadow > 0
            else []
        )
        return out, near, shade

    def _near(self, p: WaterPath, box: Box):
        """Rays (a :class:`WaterPath`) passing within reach of a box at its mid-height (to bound its window)."""
        L, W, H = box.size_m
        surface, dir_water = p.surface_ne, p.dir_water
        t = (box.ned[2] + H / 2 - p.down_m) / dir_water[:, 2]
        dist = np.hypot(
            surface[:, 0] + dir_water[:, 0] * t - box.ned[0],
            surface[:, 1] + dir_water[:, 1] * t - box.ned[1],
        )
        return p.wet & (
            dist < 0.5 * np.hypot(L, W) + 0.5 * H * np.tan(np.arcsin(1 / self.n_water)) + 0.05
        )

    def _shade_near(self, floor_n, floor_e, wet, box: Box):
        """Rays whose floor point is within reach of a box's shadow (to bound the shadow's window)."""
        L, W, H = box.size_m
        sun = self.sunlight_in_water
        mid = box.ned[2] + H / 2
        centre = box.ned[:2] + sun[:2] * (self.sc.site.floor_depth_m - mid) / sun[2]
        reach = 0.5 * np.hypot(L, W) + 0.5 * H * np.hypot(sun[0], sun[1]) / sun[2] + 0.05
        return wet & (np.hypot(floor_n - centre[0], floor_e - centre[1]) < reach)

    def _window(self, near, scale: int, height: int, width: int):
        """The window ``(v0, v1, u0, u1)`` of an image ``scale`` pixels per grid step around a grid mask, or None."""
        rows, cols = np.nonzero(near)
        if len(rows) == 0:
            return None
        v0, v1 = max(0, scale * (rows.min() - 2)), min(height, scale * (rows.max() + 1))
        u0, u1 = max(0, scale * (cols.min() - 2)), min(width, scale * (cols.max() + 1))
        if v0 >= v1 or u0 >= u1:
            return None
        return v0, v1, u0, u1

    def _in_shadow(self, points_ned, boxes, skip=None):
        """Where the sunlight to points (N, 3) is blocked by one of the boxes (but box number ``skip``)."""
        blocked = np.zeros(len(points_ned), bool)
        up = np.broadcast_to(-self.sunlight_in_water, points_ned.shape)
        for k, b in enumerate(boxes):
            if k != skip:
                origin, direction = to_body(points_ned[:, :2], up, b, points_ned[:, 2])
                blocked |= hit_box(origin, direction, b.size_m)[0]
        return blocked

    def _floor_lit(self, view: View, boxes, shade, floor_waves):
        """The sunlit share of each floor pixel in the shadows' windows: ``(rows, cols, lit)``, or None."""
        c = self.coarse
        windows = [
            w for m in shade if (w := self._window(m, c, self.floor_h, self.floor_w)) is not None
        ]
        if not windows:
            return None
        rows, cols = pixels_of(windows, self.floor_h, self.floor_w)
        ss = self.sc.render.supersample
        uu, vv = subsamples(rows, cols, ss, self.floor_div)
        ray = pixel_rays(self.camera, uu.ravel(), vv.ravel())
        p = water_path(ray, view, self.n_water, floor_waves)
        depth = self.sc.site.floor_depth_m
        floor = np.column_stack(
            [
                p.surface_ne
                + p.dir_water[:, :2] * ((depth - p.down_m) / p.dir_water[:, 2])[:, None],
                np.full(len(ray), depth),
            ]
        )
        blocked = p.wet & self._in_shadow(floor, boxes)
        return rows, cols, 1.0 - blocked.reshape(len(rows), ss * ss).mean(axis=1)

    def _caustic_texture(self, tau_s):
        """The two caustic layers drifting over the floor, combined (in floor-texture pixels)."""
        (a, b), layers = self.caustics, []
        for tex, scale, (vn, ve) in zip((a, b), (1.0, 1.37), self.caustic_drift_ne):
            shift = np.array([ve, -vn]) * tau_s / FLOOR_M_PER_PX
            M = np.array([[1 / scale, 0, shift[0] / scale], [0, 1 / scale, shift[1] / scale]])
            layers.append(
                cv2.warpAffine(
                    tex,
                    M,
                    tex.shape[::-1],
                    flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                    borderMode=cv2.BORDER_WRAP,
                )
            )
        return np.sqrt(layers[0] * layers[1])

    def _caustic_factor(self, caus, depth_m):
        """The sunlight's factor where the caustic texture is ``caus`` at ``depth_m``: over a flat surface
        1 + k·(2·caus − 0.3), k = ``[render] caustics``, the same at every depth (as before waves); under waves
        1 + k·exp(−``caustic_fade_per_m``·depth)·(caus − mean)/std: k is the light's relative flicker (standard
        deviation over mean) just below the surface, the texture's mean and std taken over it (at 1 the bright
        web is 6 times the mean, the dark between half of it)."""
        k = self.sc.render.caustics
        if self.waves is None:
            return 1.0 + k * (2.0 * caus - 0.3)
        fade = np.exp(-self.sc.waves.caustic_fade_per_m * np.asarray(depth_m, np.float32))
        return 1.0 + (k / self.caustic_std) * fade * (caus - self.caustic_mean)

    def _caustic_light(self, texture_now, points_ned):
        """The sunlight's factor (N,) at points (N, 3) under waves: the frame's caustic texture there."""
        caus = texture.sample(
            texture_now,
            points_ned[:, 1] / FLOOR_M_PER_PX,
            -points_ned[:, 0] / FLOOR_M_PER_PX,
            cv2.INTER_LINEAR,
            cv2.BORDER_WRAP,
        )
        return self._caustic_factor(caus, points_ned[:, 2])

    def _rays(self, rows, cols):
        """:func:`pixel_rays` (P·ss·ss, 3) of pixels (rows, cols) at :func:`subsamples`, from a cache of
        ``RAY_TILE``-pixel square tiles (the UUV's windows cover the same pixels frame after frame; each ray is
        OpenCV's for its own point, whichever points it is computed with: the same numbers)."""
        ss, t = self.sc.render.supersample, RAY_TILE
        per_row = self.camera.width // t + 1  # tiles in a row of them
        tiles = rows // t * per_row + cols // t
        needed, slot = np.unique(tiles, return_inverse=True)
        for key in needed:
            if key in self._ray_tiles:
                self._ray_tiles.move_to_end(key)
                continue
            r0, c0 = divmod(int(key), per_row)
            tv, tu = np.mgrid[r0 * t : (r0 + 1) * t, c0 * t : (c0 + 1) * t]
            su, sv = subsamples(tv.ravel(), tu.ravel(), ss)
            self._ray_tiles[key] = pixel_rays(self.camera, su.ravel(), sv.ravel()).reshape(
                t, t, ss, ss, 3
            )
        stack = np.stack([self._ray_tiles[key] for key in needed])
        while len(self._ray_tiles) > RAY_TILES_KEPT:  # the least recently used go
            self._ray_tiles.popitem(last=False)
        return stack[slot.ravel(), rows % t, cols % t].reshape(-1, 3)

    def _boxes(self, view: View, img, boxes, near, caustics=None) -> tuple:
        """Blend the boxes (the UUV first when it is not hidden) into ``img`` (H, W, 3) in windows around them; returns
        per box its bounding box, or None where it cannot be seen: no pixel mostly covered, less than half of it
        showing (the rest behind another box), or its contrast below the sensor noise. ``caustics``: the frame's
        :meth:`_caustic_texture` where it lights the boxes too (under waves), else None.

        Contrast: the RMS change (grey levels) the vehicle makes to the pixels of its box, before
        noise. Deep in turbid water it fades into the water's colour and drops below the noise's
        ``noise_sigma`` (at least ``MIN_CONTRAST``): the UUV is then drawn but counts as not visible.
        """
        cam = self.camera
        unseen = (None,) * len(boxes)
        windows = [
            w
            for m in near
            if (w := self._window(m, self.coarse * self.floor_div, cam.height, cam.width))
            is not None
        ]
        if not windows:
            return unseen
        vv, uu = pixels_of(windows, cam.height, cam.width)
        ss = self.sc.render.supersample
        ray = self._rays(vv, uu)
        p = water_path(ray, view, self.n_water, self.exact_surface(view))
        surface, dir_water = p.surface_ne, p.dir_water
        owner, nearest, hits = np.full(len(ray), -1), np.full(len(ray), np.inf), []
        for k, b in enumerate(boxes):
            if floats(b):
                hit, t_in, face, point = self._deck(ray, view, b)
                order = np.where(hit, -1.0, np.inf)  # above the water: before anything in it
            else:
                origin, direction = to_body(surface, dir_water, b, p.down_m)
                origin[~p.wet] = np.nan
                hit, t_in, face, point = hit_box(origin, direction, b.size_m)
                hit &= np.isfinite(origin[:, 0])
                order = t_in
            hits.append((hit, t_in, face, point))
            closer = hit & (order < nearest)
            owner[closer], nearest[closer] = k, order[closer]
        if not (owner >= 0).any():
            return unseen
        colour = np.zeros((len(ray), 3))
        for k, (b, (_, t_in, face, point)) in enumerate(zip(boxes, hits)):
            own = owner == k
            if not own.any():
                continue
            if floats(b):  # sunlit in the air: no water, no surface between
                albedo = buoy_albedo(point[own], face[own], self.sc.buoy.radius_m)
                colour[own] = albedo * self.sc.render.exposure
                continue
            gain, veil = self._through_water(b.ned[2] + point[own, 2], t_in[own])
            at = np.column_stack(
                [
                    surface[own] + dir_water[own, :2] * t_in[own, None],
                    p.down_m[own] + dir_water[own, 2] * t_in[own],
                ]
            )
            light = 1.0 if caustics is None else self._caustic_light(caustics, at)
            if self.shadow > 0:
                light = np.where(self._in_shadow(at, boxes, skip=k), 1.0 - self.shadow, light)
            if self.shadow > 0 or caustics is not None:
                gain = gain * light[:, None]
            keep, add = self._surface(
                ray[own], view, None if p.normal_up is None else p.normal_up[own]
            )
            paint_box = (
                partial(buoy_albedo, radius_m=self.sc.buoy.radius_m)
                if b.look == "buoy"
                else ALBEDO[b.look]
            )
            colour[own] = (paint_box(point[own], face[own]) * gain + veil) * keep + add
        n = ss * ss
        cover = (owner >= 0).reshape(len(vv), n).mean(axis=1)[:, None]
        mean_hit = colour.reshape(len(vv), n, 3).sum(axis=1) / np.maximum(cover * n, 1)
        before = img[vv, uu]
        img[vv, uu] = before * (1 - cover) + mean_hit * cover
        colour = colour.reshape(len(vv), n, 3)
        return tuple(
            self._seen((owner == k).reshape(len(vv), n), hits[k][0].sum(), colour, before, vv, uu)
            for k in range(len(boxes))
        )

    def _deck(self, ray_cv, view: View, box: Box):
        """:func:`hit_box` of camera rays (N, 3) straight through the air with a floating box's top face (its deck at
        the surface, :func:`floats`): the rays that meet its top only (the sides are under the water)."""
        d = ray_cv @ view.R_ned_from_cv.T.astype(ray_cv.dtype)
        origin, direction = to_body(
            np.broadcast_to(view.camera_ned[:2], (len(d), 2)),
            d,
            box,
            np.full(len(d), view.camera_ned[2]),
        )
        hit, t_in, face, point = hit_box(origin, direction, box.size_m)
        return hit & (face == 2), t_in, face, point

    def _seen(self, own, rays_hit: int, colour, before, vv, uu):
        """A box's bounding box (x, y, w, h) where it can be seen, else None (see :meth:`_boxes`).

        ``own`` (P, n): which of each window pixel's n rays see it first; ``rays_hit``: how many meet it at all;
        ``colour`` (P, n, 3) what each ray sees; ``before`` (P, 3) the pixels without the boxes; ``vv``, ``uu`` the
        pixels' rows and columns.
        """
        n = own.shape[1]
        if own.sum() < 0.5 * rays_hit:  # mostly behind another box
            return None
        cover = own.mean(axis=1)[:, None]
        mean_hit = np.where(own[..., None], colour, 0.0).sum(axis=1) / np.maximum(cover * n, 1)
        shown = cover[:, 0] > 0.25
        if not shown.any():
            return None
        x, y = uu[shown].min(), vv[shown].min()
        w, h = uu[shown].max() - x + 1, vv[shown].max() - y + 1
        r0, c0 = vv.min(), uu.min()
        change = np.zeros((vv.max() - r0 + 1, uu.max() - c0 + 1, 3))
        change[vv - r0, uu - c0] = (mean_hit - before) * cover
        grey = change[y - r0 : y - r0 + h, x - c0 : x - c0 + w] @ GREY_BGR
        if np.sqrt(np.mean(grey**2)) < max(self.sc.render.noise_sigma, MIN_CONTRAST):
            return None
        return int(x), int(y), int(w), int(h)

    def render(self, view: View):
        """One frame: ``(image (H, W, 3) uint8 BGR, UUV bounding box (x, y, w, h) or None where it cannot be seen)``."""
        img, seen = self.render_seen(view)
        return img, seen[0]

    def render_seen(self, view: View, noise_at: tuple[int, int] | None = None):
        """One frame: ``(image (H, W, 3) uint8 BGR, boxes)``, ``boxes`` the bounding box (x, y, w, h) of the UUV and of
        each of ``view.others`` in turn, or None where it cannot be seen (the UUV also where it is hidden).

        ``noise_at``: the (row, column) the frame's sensor noise is cut from the noise field at; by default the next
        draw of the renderer's own generator (frames rendered in turn). Frames rendered apart (in several
        processes) are given theirs from :func:`noise_offsets`: the same frames either way.
        """
        boxes = ((self.uuv_box(view),) if view.uuv_visible else ()) + tuple(view.others)
        floor_waves = self.floor_surface(view)
        fields, near, shade = self._coarse(view, boxes, floor_waves)
        fmap = np.ascontiguousarray(fields["map"])
        albedo = cv2.remap(self.floor, fmap, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        gain = fields["gain"]
        k = self.sc.render.caustics
        sun = None  # the sunlight's factor on the floor: the caustics, and the shadows
        # the frame's caustic texture where it lights the vehicles too (under waves)
        caustics = None
        if k > 0:
            texture_now = self._caustic_texture(view.tau_s)
            caus = cv2.remap(texture_now, fmap, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
            sun = self._caustic_factor(caus, self.sc.site.floor_depth_m)
            caustics = texture_now if self.waves is not None else None
        lit = self._floor_lit(view, boxes, shade, floor_waves) if shade else None
        if lit is not None:
            rows, cols, share = lit
            sun = np.ones((self.floor_h, self.floor_w), np.float32) if sun is None else sun
            sun[rows, cols] = share * sun[rows, cols] + (1.0 - share) * (1.0 - self.shadow)
        if sun is not None:
            gain = gain * sun[..., None]
        img = albedo * gain + fields["veil"]
        if self.sc.render.glint > 0 and self.waves is None:
            smap = np.ascontiguousarray(fields["sparkle_map"])
            smap[..., 1] += 37.0 * view.tau_s  # ripples moving over the surface
            sparkle = cv2.remap(
                self.sparkle, smap, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP
            )
            img += fields["glint"] * sparkle[..., None]
        if self.floor_div > 1:
            img = cv2.resize(
                img, (self.camera.width, self.camera.height), interpolation=cv2.INTER_LINEAR
            )
        seen = (() if view.uuv_visible else (None,)) + (
            self._boxes(view, img, boxes, near, caustics) if boxes else ()
        )
        if self.sc.render.noise_sigma > 0:
            dy, dx = _noise_offset(self.noise_rng) if noise_at is None else noise_at
            img = cv2.add(
                img, self.noise[dy : dy + self.camera.height, dx : dx + self.camera.width]
            )
        return np.clip(img + 0.5, 0, 255, out=img).astype(np.uint8), seen
