"""Per-pixel ray casting of the underwater scene as the UAV's camera sees it.

Each pixel's ray comes from OpenCV's undistortion (:func:`~sim_fixtures.geometry.pixel_rays`,
so the image carries the lens distortion), is turned into NED by the camera's true
attitude, bent at the flat surface by Snell's law in vector form
(:func:`~sim_fixtures.geometry.refract_into_water`), and followed to the seafloor (a world-fixed texture) or to the UUV, a box of the
BlueROV2's size whose reference point is the centre of its top face. Light is
attenuated along the water path per colour channel; caustics move over the
floor; the surface reflects the sky (Schlick's Fresnel) and, optionally, the sun.
The UUV is ray cast only in a window around it, with supersampling.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from . import texture
from .geometry import SimCamera, pixel_rays, refract_into_water
from .scenario import Scenario

FLOOR_M_PER_PX = 0.015
SKY_BGR = np.array([235.0, 215.0, 200.0], np.float32)
GLINT_HAZE = 0.1  # the smooth part of the sun's glint; the rest comes in sparkles from surface ripples
MIN_CONTRAST = 1.0  # grey levels: the UUV counts as visible only if it changes its box at least this much (RMS)
GREY_BGR = np.array([0.114, 0.587, 0.299])  # luma weights (as cv2.COLOR_BGR2GRAY)


@dataclass(frozen=True)
class View:
    """The true geometry of one frame (world NED, metres, radians)."""

    R_ned_from_cv: np.ndarray  # (3, 3)
    camera_ned: np.ndarray  # (3,)
    uuv_ned: np.ndarray  # (3,) centre of the UUV's top face
    uuv_heading: float
    uuv_visible: bool
    tau_s: float


def water_path(ray_cv, view: View, n_water: float):
    """Where camera rays cross the surface and how they continue in the water.

    ``ray_cv`` (N, 3) unit rays in the camera frame. Returns ``(surface_ne (N, 2),
    dir_water (N, 3) NED unit, wet (N,))``; ``wet`` is False for rays that do not
    point down at the water (their other values are 0).
    """
    d = ray_cv @ view.R_ned_from_cv.T.astype(ray_cv.dtype)
    wet = d[:, 2] > 1e-3
    d = np.where(wet[:, None], d, np.array([0.0, 0.0, 1.0], ray_cv.dtype))
    height = -view.camera_ned[2]
    surface = view.camera_ned[:2].astype(ray_cv.dtype) + d[:, :2] * (height / d[:, 2])[:, None]
    return surface, refract_into_water(d, n_water).astype(ray_cv.dtype), wet


def to_body(surface_ne, dir_water, view: View):
    """Ray origins (on the surface) and directions in the UUV's body frame.

    Body frame: origin at the top face's centre, x forward, y right, z down (the UUV is level).
    """
    c, s = np.cos(view.uuv_heading), np.sin(view.uuv_heading)
    dn = surface_ne[:, 0] - view.uuv_ned[0]
    de = surface_ne[:, 1] - view.uuv_ned[1]
    origin = np.stack([c * dn + s * de, -s * dn + c * de, np.full_like(dn, -view.uuv_ned[2])], axis=-1)
    direction = np.stack([c * dir_water[:, 0] + s * dir_water[:, 1], -s * dir_water[:, 0] + c * dir_water[:, 1],
                          dir_water[:, 2]], axis=-1)
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
    hit = (t_in <= t_far.min(axis=1)) & (t_in >= 0)  # 0: a top face at the surface, where the rays enter
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
    col[(np.abs(y) < 0.03) & (x > 0.16) & (x < 0.2)] = (40.0, 200.0, 235.0)  # yellow dome rim, the nose
    shade = np.where(face_axis == 2, 1.0, 0.55)
    return col * shade[:, None]


class Renderer:
    """Renders frames of one scenario; textures and rays are made once.

    The floor's smooth terms (texture coordinates, attenuation, Fresnel, glint) are
    computed exactly on a grid every ``COARSE`` floor pixels and interpolated
    bilinearly (the mapping is smooth, so this is exact to far below a pixel). The
    floor is looked up at the image's resolution divided by ``floor_div`` (2 for even
    sizes from 1200 px wide: the 1.5 cm texture has no finer detail at usual heights) and
    scaled up; the UUV is always ray cast per image pixel, supersampled.
    """

    COARSE = 4

    def __init__(self, sc: Scenario, camera: SimCamera):
        self.sc = sc
        self.camera = camera
        rng = np.random.default_rng([sc.seed, 202])
        self.n_water = sc.site.refractive_index
        self.atten = np.asarray(sc.site.attenuation_bgr_per_m, np.float32)
        self.water_bgr = np.asarray(sc.site.water_bgr, np.float32)
        c = self.COARSE
        self.floor_div = div = 2 if camera.width >= 1200 and camera.width % 2 == camera.height % 2 == 0 else 1
        self.floor_w, self.floor_h = -(-camera.width // div), -(-camera.height // div)
        self.grid_w, self.grid_h = -(-self.floor_w // c) + 2, -(-self.floor_h // c) + 2
        v, u = np.mgrid[0 : self.grid_h, 0 : self.grid_w].astype(np.float64)
        # grid point j sits at floor pixel c*(j-1) + (c-1)/2, so cv2.resize by c lands on floor pixel
        # centres (offset c); floor pixel i is centred on image pixel div*i + (div-1)/2
        fu, fv = c * (u - 1) + (c - 1) / 2, c * (v - 1) + (c - 1) / 2
        self.grid_rays = pixel_rays(camera, div * fu + (div - 1) / 2, div * fv + (div - 1) / 2).reshape(-1, 3)
        self.floor = texture.seafloor(rng, m_per_px=FLOOR_M_PER_PX)
        self.caustics = (texture.caustics(rng), texture.caustics(rng))
        self.sparkle = np.clip(texture.fractal_noise(rng, 512, 0.6) - 1.5, 0.0, None)
        margin = 64
        self.noise = (rng.standard_normal((camera.height + margin, camera.width + margin, 3))
                      * sc.render.noise_sigma).astype(np.float32)
        self.noise_rng = np.random.default_rng([sc.seed, 303])
        el, az = np.radians(sc.render.sun_elevation_deg), np.radians(sc.render.sun_azimuth_deg)
        self.sun_up_ned = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])

    # --- geometry shared with the tests ------------------------------------------------------------
    def body_rays(self, u, v, view: View):
        """Body-frame origins and directions of the rays through distorted pixels (u, v)."""
        ray = pixel_rays(self.camera, np.ravel(u), np.ravel(v))
        surface, dir_water, wet = water_path(ray, view, self.n_water)
        origin, direction = to_body(surface, dir_water, view)
        origin[~wet] = np.nan
        return origin, direction, ray

    def top_face_xy(self, u, v, view: View):
        """Body (x, y) where the rays of pixels (u, v) meet the top face's plane, (N, 2)."""
        origin, direction, _ = self.body_rays(u, v, view)
        t = -origin[:, 2] / direction[:, 2]
        return origin[:, :2] + t[:, None] * direction[:, :2]

    # --- light ---------------------------------------------------------------------------------------
    def _through_water(self, light_depth_m, path_m):
        """``(gain, veil)``: seen colour = albedo·gain + veil for a surface at ``light_depth_m``
        seen through ``path_m`` of water (per BGR channel, arrays (N, 3))."""
        a = self.atten
        trans = np.exp(-a * path_m[:, None])
        return self.sc.render.exposure * np.exp(-a * light_depth_m[:, None]) * trans, self.water_bgr * (1.0 - trans)

    def _surface(self, ray_cv, view: View):
        """``(keep, add)`` of the water surface for camera rays: seen = underwater·keep + add.

        ``keep`` is 1 − Fresnel reflectance (Schlick) (N, 1); ``add`` the reflected sky
        plus the smooth part of the sun's glint (N, 3).
        """
        d = ray_cv @ view.R_ned_from_cv.T
        cos_i = np.clip(d[:, 2], 0.0, 1.0)
        n = self.n_water
        f0 = ((n - 1) / (n + 1)) ** 2
        fresnel = (f0 + (1 - f0) * (1 - cos_i) ** 5)[:, None]
        add = SKY_BGR * fresnel
        if self.sc.render.glint > 0:
            align = (d * np.array([1.0, 1.0, -1.0])) @ self.sun_up_ned
            add = add + (GLINT_HAZE * self.sc.render.glint * 255.0 * np.exp((align - 1.0) / 0.02))[:, None]
        return 1.0 - fresnel, add

    # --- image ---------------------------------------------------------------------------------------
    def _coarse(self, view: View):
        """Floor-resolution smooth fields from the coarse grid (dict of float32 arrays), and the
        grid points whose rays pass near the UUV."""
        surface, dir_water, wet = water_path(self.grid_rays, view, self.n_water)
        depth = self.sc.site.floor_depth_m
        t = depth / dir_water[:, 2]
        fn = surface[:, 0] + dir_water[:, 0] * t
        fe = surface[:, 1] + dir_water[:, 1] * t
        gain, veil = self._through_water(np.full(len(t), depth), t)
        keep, add = self._surface(self.grid_rays, view)
        gain = np.where(wet[:, None], gain * keep, 0.0)
        veil = np.where(wet[:, None], veil * keep + add, SKY_BGR)
        fields = {"map": np.stack([fe, -fn], axis=-1) / FLOOR_M_PER_PX, "gain": gain, "veil": veil}
        if self.sc.render.glint > 0:
            fields["sparkle_map"] = np.stack([surface[:, 1], -surface[:, 0]], axis=-1) / 0.01
            fields["glint"] = (add - SKY_BGR * (1 - keep))[:, :1] / GLINT_HAZE  # grey: any channel
        c = self.COARSE
        out = {}
        for key, f in fields.items():
            grid = f.reshape(self.grid_h, self.grid_w, -1).astype(np.float32)
            full = cv2.resize(grid, (self.grid_w * c, self.grid_h * c), interpolation=cv2.INTER_LINEAR)
            out[key] = full.reshape(self.grid_h * c, self.grid_w * c, -1)[c : c + self.floor_h, c : c + self.floor_w]
        near = self._near_uuv(surface, dir_water, wet, view).reshape(self.grid_h, self.grid_w)
        return out, near

    def _near_uuv(self, surface, dir_water, wet, view: View):
        """Rays passing within reach of the UUV at its mid-height (to bound its window)."""
        L, W, H = self.sc.uuv.size_m
        t = (view.uuv_ned[2] + H / 2) / dir_water[:, 2]
        dist = np.hypot(surface[:, 0] + dir_water[:, 0] * t - view.uuv_ned[0],
                        surface[:, 1] + dir_water[:, 1] * t - view.uuv_ned[1])
        return wet & (dist < 0.5 * np.hypot(L, W) + 0.5 * H * np.tan(np.arcsin(1 / self.n_water)) + 0.05)

    def _caustic_texture(self, tau_s):
        """The two caustic layers drifting over the floor, combined (in floor-texture pixels)."""
        (a, b), layers = self.caustics, []
        for tex, scale, (vn, ve) in ((a, 1.0, (0.11, 0.07)), (b, 1.37, (-0.05, 0.13))):
            shift = np.array([ve, -vn]) * tau_s / FLOOR_M_PER_PX
            M = np.array([[1 / scale, 0, shift[0] / scale], [0, 1 / scale, shift[1] / scale]])
            layers.append(cv2.warpAffine(tex, M, tex.shape[::-1], flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                         borderMode=cv2.BORDER_WRAP))
        return np.sqrt(layers[0] * layers[1])

    def _uuv(self, view: View, img, near):
        """Blend the UUV into ``img`` (H, W, 3) in a window around it; returns its bounding box, or None
        where it cannot be seen: no pixel mostly covered, or its contrast below the sensor noise.

        Contrast: the RMS change (grey levels) the vehicle makes to the pixels of its box, before
        noise. Deep in turbid water it fades into the water's colour and drops below the noise's
        ``noise_sigma`` (at least ``MIN_CONTRAST``): the UUV is then drawn but counts as not visible.
        """
        rows, cols = np.nonzero(near)
        if len(rows) == 0:
            return None
        c, cam = self.COARSE * self.floor_div, self.camera
        v0, v1 = max(0, c * (rows.min() - 2)), min(cam.height, c * (rows.max() + 1))
        u0, u1 = max(0, c * (cols.min() - 2)), min(cam.width, c * (cols.max() + 1))
        if v0 >= v1 or u0 >= u1:
            return None
        ss = self.sc.render.supersample
        sub = (np.arange(ss) + 0.5) / ss - 0.5
        vv, uu, sv, su = np.meshgrid(np.arange(v0, v1), np.arange(u0, u1), sub, sub, indexing="ij")
        origin, direction, ray = self.body_rays(uu + su, vv + sv, view)
        hit, t_in, face, point = hit_box(origin, direction, self.sc.uuv.size_m)
        hit &= np.isfinite(origin[:, 0])
        if not hit.any():
            return None
        gain, veil = self._through_water(view.uuv_ned[2] + point[hit, 2], t_in[hit])
        keep, add = self._surface(ray[hit], view)
        colour = np.zeros((len(hit), 3))
        colour[hit] = (uuv_albedo(point[hit], face[hit]) * gain + veil) * keep + add
        shape = (v1 - v0, u1 - u0, ss * ss)
        cover = hit.reshape(shape).mean(axis=2)[..., None]
        mean_hit = colour.reshape(shape + (3,)).sum(axis=2) / np.maximum(cover * ss * ss, 1)
        win = img[v0:v1, u0:u1]
        change = (mean_hit - win) * cover
        win[:] = win * (1 - cover) + mean_hit * cover
        ys, xs = np.nonzero(cover[..., 0] > 0.25)
        if len(ys) == 0:
            return None
        x, y = u0 + xs.min(), v0 + ys.min()
        w, h = u0 + xs.max() - x + 1, v0 + ys.max() - y + 1
        grey = change[y - v0 : y - v0 + h, x - u0 : x - u0 + w] @ GREY_BGR
        if np.sqrt(np.mean(grey**2)) < max(self.sc.render.noise_sigma, MIN_CONTRAST):
            return None
        return int(x), int(y), int(w), int(h)

    def render(self, view: View):
        """One frame: ``(image (H, W, 3) uint8 BGR, UUV bounding box (x, y, w, h) or None where it cannot be seen)``."""
        fields, near = self._coarse(view)
        fmap = np.ascontiguousarray(fields["map"])
        albedo = cv2.remap(self.floor, fmap, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        gain = fields["gain"]
        k = self.sc.render.caustics
        if k > 0:
            caus = cv2.remap(self._caustic_texture(view.tau_s), fmap, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
            gain = gain * (1.0 + k * (2.0 * caus - 0.3))[..., None]
        img = albedo * gain + fields["veil"]
        if self.sc.render.glint > 0:
            smap = np.ascontiguousarray(fields["sparkle_map"])
            smap[..., 1] += 37.0 * view.tau_s  # ripples moving over the surface
            sparkle = cv2.remap(self.sparkle, smap, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
            img += fields["glint"] * sparkle[..., None]
        if self.floor_div > 1:
            img = cv2.resize(img, (self.camera.width, self.camera.height), interpolation=cv2.INTER_LINEAR)
        box = self._uuv(view, img, near) if view.uuv_visible else None
        if self.sc.render.noise_sigma > 0:
            dy, dx = self.noise_rng.integers(0, 64, 2)
            img = cv2.add(img, self.noise[dy : dy + self.camera.height, dx : dx + self.camera.width])
        return np.clip(img + 0.5, 0, 255, out=img).astype(np.uint8), box
