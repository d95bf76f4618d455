"""Synthetic calibration images: a board texture seen through a known camera at known poses.

Every output pixel (supersampled ``ss``×``ss``) is undistorted into a ray with the
true intrinsics and distortion, intersected with the board plane, and the board
texture is sampled there; the supersamples are then averaged, blurred and given
noise. The board's corners therefore land exactly where ``cv2.projectPoints``
puts them (checked in test_calibrate.py), and a calibration can be compared with
the camera that made the images.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from localizer.camera import undistort

BACKGROUND = 90  # grey around the board


@dataclass(frozen=True)
class TrueCamera:
    width: int = 800
    height: int = 600
    fx: float = 620.0
    fy: float = 622.5
    cx: float = 404.3
    cy: float = 296.8
    distortion: tuple = (-0.26, 0.085, 0.0007, -0.0004, -0.012)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])


@dataclass(frozen=True)
class Texture:
    image: np.ndarray  # uint8 grey
    px_per_m: float
    # texture coordinate of the board's (0, 0) (top-left of its squares), both axes
    origin_px: float
    size_m: tuple[float, float]  # the squares' area, width and height


def chessboard_texture(cols: int, rows: int, square_m: float, px_per_square: int = 64) -> Texture:
    """A chessboard of ``cols``×``rows`` squares with a white quiet zone one square wide."""
    sq = px_per_square
    img = np.full(((rows + 2) * sq, (cols + 2) * sq), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                img[(r + 1) * sq : (r + 2) * sq, (c + 1) * sq : (c + 2) * sq] = 0
    return Texture(img, sq / square_m, sq - 0.5, (cols * square_m, rows * square_m))


def charuco_texture(
    cols, rows, square_m, marker_m, dictionary="DICT_5X5_100", px_per_square=64
) -> Texture:
    """OpenCV's own ChArUco image (``CharucoBoard.generateImage``) with a white margin one square wide."""
    board = cv2.aruco.CharucoBoard(
        (cols, rows),
        square_m,
        marker_m,
        cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)),
    )
    sq = px_per_square
    img = board.generateImage(((cols + 2) * sq, (rows + 2) * sq), marginSize=sq, borderBits=1)
    return Texture(img, sq / square_m, sq - 0.5, (cols * square_m, rows * square_m))


@lru_cache(maxsize=4)
def _rays(cam: TrueCamera, ss: int):
    """Undistorted normalized coordinates of every supersample of the image."""
    u = (np.arange(cam.width * ss) + 0.5) / ss - 0.5
    v = (np.arange(cam.height * ss) + 0.5) / ss - 0.5
    uu, vv = np.meshgrid(u, v)
    x, y = undistort((uu - cam.cx) / cam.fx, (vv - cam.cy) / cam.fy, cam.distortion)
    return x, y


def board_points(tex: Texture, n: int = 12) -> np.ndarray:
    """Points along the outline of the board's squares area (metres, board frame, z = 0)."""
    w, h = tex.size_m
    s = np.linspace(0, 1, n)
    edges = [
        np.stack([s * w, 0 * s], 1),
        np.stack([s * w, 0 * s + h], 1),
        np.stack([0 * s, s * h], 1),
        np.stack([0 * s + w, s * h], 1),
    ]
    pts = np.concatenate(edges)
    return np.concatenate([pts, np.zeros((len(pts), 1))], 1)


def project(cam: TrueCamera, rvec, tvec, pts: np.ndarray) -> np.ndarray:
    img, _ = cv2.projectPoints(pts.astype(np.float64), rvec, tvec, cam.K, np.array(cam.distortion))
    return img.reshape(-1, 2)


def render(
    cam: TrueCamera,
    tex: Texture,
    rvec,
    tvec,
    *,
    ss: int = 2,
    blur: float = 0.7,
    noise: float = 2.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """The grey image of the board at pose (rvec, tvec): board frame → camera frame."""
    x, y = _rays(cam, ss)
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
    # board (X, Y, 1) → ray
    H = np.column_stack([R[:, 0], R[:, 1], np.asarray(tvec, dtype=float).ravel()])
    Hi = np.linalg.inv(H)
    a = Hi[0, 0] * x + Hi[0, 1] * y + Hi[0, 2]
    b = Hi[1, 0] * x + Hi[1, 1] * y + Hi[1, 2]
    c = Hi[2, 0] * x + Hi[2, 1] * y + Hi[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = np.where(c > 0, a / c, -1e3)
        Y = np.where(c > 0, b / c, -1e3)
    mx = (tex.origin_px + X * tex.px_per_m).astype(np.float32)
    my = (tex.origin_px + Y * tex.px_per_m).astype(np.float32)
    sup = cv2.remap(
        tex.image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=BACKGROUND
    )
    img = cv2.resize(sup.astype(np.float32), (cam.width, cam.height), interpolation=cv2.INTER_AREA)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if noise > 0:
        img = img + (rng or np.random.default_rng(0)).normal(0, noise, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _rot(rx, ry, rz) -> np.ndarray:
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rx @ Ry @ Rz


def poses(
    cam: TrueCamera,
    tex: Texture,
    n: int,
    *,
    seed: int = 1,
    distance_m=(0.38, 0.6),
    tilt_deg=40.0,
    spread: float = 1.0,
    margin_px: float = 12.0,
):
    """``n`` board poses ``(rvec, tvec)``, fully visible, aimed across the image.

    Each pose aims the board's centre at a target point; targets cycle through the
    image's corners, edges and centre (scaled by ``spread``: 0 keeps every view in
    the centre), and the board is slid from the centre towards its target as far as
    it stays ``margin_px`` inside the image.
    """
    rng = np.random.default_rng(seed)
    w, h = tex.size_m
    targets = [(-1, -1), (1, 1), (1, -1), (-1, 1), (0, 0), (0, -1), (1, 0), (0, 1), (-1, 0)]
    outline = board_points(tex)
    out = []
    while len(out) < n:
        tx, ty = targets[len(out) % len(targets)]
        tilt = np.radians(rng.uniform(-tilt_deg, tilt_deg, 2))
        R = _rot(tilt[0], tilt[1], np.radians(rng.uniform(-25, 25)))
        rvec = cv2.Rodrigues(R)[0].ravel()
        z = rng.uniform(*distance_m)
        best, best_score = None, -1.0
        for fu in np.linspace(1.0, 0.0, 21):  # the (u, v) slide that gets closest to the target
            for fv in np.linspace(1.0, 0.0, 21):
                if fu + fv <= best_score:
                    continue
                ux = cam.cx + fu * spread * tx * (cam.width / 2)
                vy = cam.cy + fv * spread * ty * (cam.height / 2)
                xn, yn = undistort((ux - cam.cx) / cam.fx, (vy - cam.cy) / cam.fy, cam.distortion)
                tvec = z * np.array([float(xn), float(yn), 1.0]) - R @ np.array([w / 2, h / 2, 0.0])
                pts = project(cam, rvec, tvec, outline)
                cam_z = (R @ outline.T).T[:, 2] + tvec[2]
                if (
                    np.all(cam_z > 0.05)
                    and np.all(pts > margin_px)
                    and np.all(pts < np.array([cam.width, cam.height]) - 1 - margin_px)
                ):
                    best, best_score = tvec, fu + fv
        if best is not None:
            out.append((rvec, best))
    return out
