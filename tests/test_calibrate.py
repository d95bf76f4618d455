"""``skyfix calibrate``: calibration on images OpenCV renders from a known camera, and imports.

The board views are rendered by ``tests/calib_render.py`` through a known camera
(intrinsics and radial-tangential distortion) at varied known poses, with blur and
noise; ``skyfix calibrate camera`` must recover that camera from the PNGs (and from a
video made of them with ffmpeg). The import files are written the way each tool
writes them (OpenCV through ``cv2.FileStorage`` itself).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest
from calib_render import TrueCamera, charuco_texture, chessboard_texture, poses, project, render

from groundstation.calibration.board import Board, Detector
from groundstation.cli import main
from localizer.calibration import Calibration
from localizer.camera import Camera, pixel_to_ray, ray_to_pixel

TRUE = TrueCamera()
CHESS = {"cols": 9, "rows": 7, "square_m": 0.03}
CHARUCO = {"cols": 8, "rows": 6, "square_m": 0.035, "marker_m": 0.026}
CHESS_ARGS = ["--board", "chessboard", "--cols", "9", "--rows", "7", "--square-m", "0.03"]
CHARUCO_ARGS = [
    "--board",
    "charuco",
    "--cols",
    "8",
    "--rows",
    "6",
    "--square-m",
    "0.035",
    "--marker-m",
    "0.026",
    "--dict",
    "DICT_5X5_100",
]
MOUNT_WATER = {
    "mount": {"attitude_source": "gimbal_device"},
    "water": {"takeoff_height_above_surface_m": 2.0},
}


def _render_folder(
    folder: Path, tex, n: int, *, cam=TRUE, seed=1, prefix="view", **pose_kw
) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed + 100)
    for i, (rvec, tvec) in enumerate(poses(cam, tex, n, seed=seed, **pose_kw)):
        cv2.imwrite(str(folder / f"{prefix}_{i:02d}.png"), render(cam, tex, rvec, tvec, rng=rng))
    return folder


@pytest.fixture(scope="module")
def chess_dir(tmp_path_factory) -> Path:
    tex = chessboard_texture(CHESS["cols"], CHESS["rows"], CHESS["square_m"])
    return _render_folder(tmp_path_factory.mktemp("chess"), tex, 20, tilt_deg=35)


@pytest.fixture(scope="module")
def charuco_dir(tmp_path_factory) -> Path:
    tex = charuco_texture(
        CHARUCO["cols"], CHARUCO["rows"], CHARUCO["square_m"], CHARUCO["marker_m"]
    )
    return _render_folder(tmp_path_factory.mktemp("charuco"), tex, 20, seed=2, tilt_deg=35)


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _read(path: Path) -> tuple[dict, dict]:
    """(``[camera]``, the quality numbers kept as ``# key = value`` comments)."""
    text = path.read_text()
    pattern = r"^# (rms_px|views_used|std_\w+) = (\S+)$"
    quality = {m[1]: float(m[2]) for m in re.finditer(pattern, text, re.MULTILINE)}
    return tomllib.loads(text)["camera"], quality


def _check_recovered(cam: dict, q: dict) -> None:
    """fx, fy, cx, cy within 0.5 %; each distortion coefficient within 3 reported sigmas; small RMS."""
    for key in ("fx", "fy", "cx", "cy"):
        true = getattr(TRUE, key)
        assert abs(cam[key] - true) <= 0.005 * true, f"{key} {cam[key]} vs {true}"
    for name, got, true in zip(("k1", "k2", "p1", "p2", "k3"), cam["distortion"], TRUE.distortion):
        sigma = q[f"std_{name}"]
        assert 0 < sigma < 0.01, f"std_{name} = {sigma}"
        assert abs(got - true) <= 3 * sigma, f"{name} {got} vs {true} (sigma {sigma})"
    assert q["rms_px"] < 0.1
    # what matters downstream: the recovered model puts rays where the true one does
    got = Camera(
        cam["width"],
        cam["height"],
        cam["fx"],
        cam["fy"],
        cam["cx"],
        cam["cy"],
        tuple(cam["distortion"]),
    )
    true = Camera(TRUE.width, TRUE.height, TRUE.fx, TRUE.fy, TRUE.cx, TRUE.cy, TRUE.distortion)
    u, v = np.meshgrid(np.linspace(0, TRUE.width - 1, 33), np.linspace(0, TRUE.height - 1, 25))
    pu, pv = ray_to_pixel(true, pixel_to_ray(got, u, v))
    assert np.max(np.hypot(pu - u, pv - v)) < 1.0


def _loads_cleanly(cam: dict, source: str) -> None:
    cal = Calibration.from_dict({"camera": cam, **MOUNT_WATER}, source=source)
    assert cal.warnings == ()
    assert cal.camera.distortion == tuple(cam["distortion"])


# --- the test images themselves ---------------------------------------------------------


def test_rendered_corners_land_where_project_points_puts_them():
    tex = chessboard_texture(CHESS["cols"], CHESS["rows"], CHESS["square_m"])
    rvec, tvec = np.array([0.25, -0.3, 0.1]), np.array([-0.12, -0.1, 0.5])
    found = Detector(Board("chessboard", **CHESS)).detect(render(TRUE, tex, rvec, tvec))
    assert found is not None
    obj, img = found
    true = project(TRUE, rvec, tvec, obj.astype(float) + [CHESS["square_m"], CHESS["square_m"], 0])
    # the detector may number the corners from the opposite end: match each to the nearest true one
    err = np.min(np.linalg.norm(img[:, None] - true[None], axis=2), axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.1 and err.max() < 0.25


# --- skyfix calibrate camera ------------------------------------------------------------


def test_chessboard_folder_recovers_the_camera(chess_dir, tmp_path, capsys):
    out = tmp_path / "cam.toml"
    code, stdout, stderr = _run(capsys, "calibrate", "camera", chess_dir, *CHESS_ARGS, "--out", out)
    assert code == 0, stderr
    cam, q = _read(out)
    _check_recovered(cam, q)
    assert q["views_used"] >= 15
    assert "never covered" not in stderr
    assert "coverage:" in stdout and "RMS reprojection error" in stdout
    text = out.read_text()
    assert "Calibrated in air" in text and "must not include water's refraction" in text
    _loads_cleanly(cam, str(out))


def test_charuco_folder_recovers_the_camera(charuco_dir, tmp_path, capsys):
    out = tmp_path / "cam.toml"
    code, _, stderr = _run(capsys, "calibrate", "camera", charuco_dir, *CHARUCO_ARGS, "--out", out)
    assert code == 0, stderr
    cam, q = _read(out)
    _check_recovered(cam, q)
    assert q["views_used"] >= 15
    _loads_cleanly(cam, str(out))


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs ffmpeg")
def test_video_of_the_views_recovers_the_camera(chess_dir, tmp_path, capsys):
    video = tmp_path / "board.mp4"
    subprocess.run(  # each view held for 3 frames, H.264 as a camera would record it
        [
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-framerate",
            "2",
            "-i",
            str(chess_dir / "view_%02d.png"),
            "-r",
            "6",
            "-c:v",
            "libx264",
            "-crf",
            "14",
            "-pix_fmt",
            "yuv420p",
            str(video),
        ],
        check=True,
    )
    out = tmp_path / "cam.toml"
    code, stdout, stderr = _run(
        capsys, "calibrate", "camera", video, *CHESS_ARGS, "--every", "3", "--out", out
    )
    assert code == 0, stderr
    n_images = len(list(chess_dir.glob("*.png")))
    assert re.search(rf"found in \d+ of {n_images} frames", stdout)
    cam, q = _read(out)
    _check_recovered(cam, q)


def test_views_from_another_camera_are_dropped_as_outliers(chess_dir, tmp_path, capsys):
    folder = tmp_path / "mixed"
    shutil.copytree(chess_dir, folder)
    other = TrueCamera(
        fx=600.0, fy=600.0, cx=390.0, cy=310.0, distortion=(0.08, 0.0, 0.0, 0.0, 0.0)
    )
    tex = chessboard_texture(CHESS["cols"], CHESS["rows"], CHESS["square_m"])
    _render_folder(folder, tex, 2, cam=other, seed=7, prefix="zoomed", tilt_deg=20)
    out = tmp_path / "cam.toml"
    code, stdout, stderr = _run(capsys, "calibrate", "camera", folder, *CHESS_ARGS, "--out", out)
    assert code == 0, stderr
    dropped = re.search(r"^dropped .*$", stdout, re.MULTILINE)
    assert dropped and "zoomed_00.png" in dropped[0] and "zoomed_01.png" in dropped[0]
    assert "view_" not in dropped[0]
    cam, q = _read(out)
    _check_recovered(cam, q)


def test_views_only_in_the_centre_warn_that_corners_are_extrapolated(tmp_path, capsys):
    tex = chessboard_texture(CHESS["cols"], CHESS["rows"], CHESS["square_m"])
    folder = _render_folder(
        tmp_path / "centre", tex, 12, seed=3, spread=0.0, distance_m=(0.7, 0.9), tilt_deg=35
    )
    out = tmp_path / "cam.toml"
    code, stdout, stderr = _run(capsys, "calibrate", "camera", folder, *CHESS_ARGS, "--out", out)
    assert code == 0
    warning = [line for line in stderr.splitlines() if "never covered" in line]
    assert len(warning) == 1
    assert all(c in warning[0] for c in ("top-left", "top-right", "bottom-left", "bottom-right"))
    assert "distortion there is extrapolated" in warning[0]
    assert "WARNING: the image's" in out.read_text()
    grid = [line.split() for line in stdout.splitlines()[-6:-2]]
    assert [int(grid[r][c]) for r, c in ((0, 0), (0, 3), (3, 0), (3, 3))] == [0, 0, 0, 0]


def test_existing_output_is_not_overwritten_without_force(chess_dir, tmp_path, capsys):
    out = tmp_path / "cam.toml"
    out.write_text("# mine\n")
    code, _, stderr = _run(capsys, "calibrate", "camera", chess_dir, *CHESS_ARGS, "--out", out)
    assert code == 2
    assert stderr.count("\n") == 1 and str(out) in stderr and "--force" in stderr
    assert out.read_text() == "# mine\n"


def test_no_board_found_is_one_line(tmp_path, capsys):
    folder = tmp_path / "blank"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"{i}.png"), np.full((120, 160), 128, np.uint8))
    code, _, stderr = _run(
        capsys, "calibrate", "camera", folder, *CHESS_ARGS, "--out", tmp_path / "c.toml"
    )
    assert code == 2
    assert stderr.count("\n") == 1 and str(folder) in stderr and "found in 0 of 3" in stderr
    assert not (tmp_path / "c.toml").exists()


@pytest.mark.parametrize(
    "argv, key",
    [
        (["--board", "charuco", "--cols", "8", "--rows", "6", "--square-m", "0.035"], "--marker-m"),
        (
            [
                "--board",
                "charuco",
                "--cols",
                "8",
                "--rows",
                "6",
                "--square-m",
                "0.035",
                "--marker-m",
                "0.04",
            ],
            "--marker-m",
        ),
        (CHARUCO_ARGS[:-1] + ["DICT_9X9_7"], "DICT_9X9_7"),
        (["--board", "chessboard", "--cols", "3", "--rows", "7", "--square-m", "0.03"], "--cols"),
    ],
)
def test_bad_options_are_one_line(chess_dir, tmp_path, capsys, argv, key):
    code, _, stderr = _run(
        capsys, "calibrate", "camera", chess_dir, *argv, "--out", tmp_path / "c.toml"
    )
    assert code == 2 and stderr.count("\n") == 1 and key in stderr


# --- skyfix calibrate import ------------------------------------------------------------

W, H = 1920, 1080
FX, FY, CX, CY = 1664.25, 1663.75, 961.125, 538.5
DIST = [-0.1205, 0.0812, 0.00041, -0.00022, 0.0]  # k3 = 0: Kalibr's radtan has no k3
EXPECTED = {"width": W, "height": H, "fx": FX, "fy": FY, "cx": CX, "cy": CY, "distortion": DIST}
K = np.array([[FX, 0, CX], [0, FY, CY], [0, 0, 1.0]])


def _opencv(path: Path, dist=DIST, **extra) -> Path:
    """As OpenCV's calibration sample saves its result."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("calibration_time", "Mon 01 Dec 2025 10:00:00")
    fs.write("image_width", W)
    fs.write("image_height", H)
    fs.write("board_width", 9)
    fs.write("board_height", 6)
    fs.write("square_size", 0.025)
    fs.write("flags", 0)
    for k, v in extra.items():
        fs.write(k, v)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", np.array([dist], dtype=float).T)
    fs.write("avg_reprojection_error", 0.21)
    fs.release()
    return path


def _kalibr(
    path: Path,
    camera_model="pinhole",
    distortion_model="radtan",
    intrinsics=(FX, FY, CX, CY),
    coeffs=DIST[:4],
) -> Path:
    """A Kalibr camchain, as kalibr_calibrate_cameras writes it (two cameras)."""
    path.write_text(f"""cam0:
  cam_overlaps: [1]
  camera_model: {camera_model}
  distortion_coeffs: [{", ".join(map(repr, coeffs))}]
  distortion_model: {distortion_model}
  intrinsics: [{", ".join(map(repr, intrinsics))}]
  resolution: [{W}, {H}]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
  - [0.9999, 0.0023, -0.0001, -0.1101]
  - [-0.0023, 0.9999, -0.0008, 0.0004]
  - [0.0001, 0.0008, 1.0, -0.0008]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [-0.28, 0.07, 0.0001, 0.0002]
  distortion_model: radtan
  intrinsics: [457.5, 456.1, 379.9, 255.2]
  resolution: [752, 480]
  rostopic: /cam1/image_raw
""")
    return path


def _ros(path: Path, model="plumb_bob", coeffs=DIST) -> Path:
    """As ROS camera_calibration (camera_calibration_parsers) writes ost.yaml."""
    k = [FX, 0, CX, 0, FY, CY, 0, 0, 1]
    p = [FX, 0, CX, 0, 0, FY, CY, 0, 0, 0, 1, 0]
    path.write_text(f"""image_width: {W}
image_height: {H}
camera_name: gimbal_camera
camera_matrix:
  rows: 3
  cols: 3
  data: [{", ".join(map(repr, k))}]
distortion_model: {model}
distortion_coefficients:
  rows: 1
  cols: {len(coeffs)}
  data: [{", ".join(map(repr, coeffs))}]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [{", ".join(map(repr, p))}]
""")
    return path


def _ros_echo(path: Path) -> Path:
    """The CameraInfo message as ``ros2 topic echo --once`` prints it."""
    path.write_text(f"""header:
  stamp:
    sec: 1764583200
    nanosec: 0
  frame_id: camera_optical
height: {H}
width: {W}
distortion_model: plumb_bob
d:
{"".join(f"- {c!r}{chr(10)}" for c in DIST)}k:
{"".join(f"- {float(c)!r}{chr(10)}" for c in K.ravel())}r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
p: [{FX}, 0.0, {CX}, 0.0, 0.0, {FY}, {CY}, 0.0, 0.0, 0.0, 1.0, 0.0]
binning_x: 0
binning_y: 0
---
""")
    return path


WRITERS = {
    "opencv.yml": _opencv,
    "opencv.xml": _opencv,
    "opencv_8coeffs.yml": lambda p: _opencv(p, dist=DIST + [0.0, 0.0, 0.0]),
    "camchain.yaml": _kalibr,
    "ost.yaml": _ros,
    "rational_zero.yaml": lambda p: _ros(p, "rational_polynomial", DIST + [0.0, 0.0, 0.0]),
    "camera_info_echo.yaml": _ros_echo,
}


@pytest.mark.parametrize("name", WRITERS)
def test_import_gives_the_same_camera_table(name, tmp_path, capsys):
    src = WRITERS[name](tmp_path / name)
    out = tmp_path / "cam.toml"
    code, _, stderr = _run(capsys, "calibrate", "import", src, "--out", out)
    assert code == 0, stderr
    cam, _ = _read(out)
    assert cam == EXPECTED
    _loads_cleanly(cam, str(out))
    assert "Calibrated in air" in out.read_text()


def test_import_keeps_k3_and_prints_without_out(tmp_path, capsys):
    dist = DIST[:4] + [-0.0123]
    code, stdout, _ = _run(capsys, "calibrate", "import", _opencv(tmp_path / "cal.yml", dist=dist))
    assert code == 0
    assert tomllib.loads(stdout)["camera"]["distortion"] == dist


def test_import_kalibr_second_camera(tmp_path, capsys):
    code, stdout, _ = _run(
        capsys, "calibrate", "import", _kalibr(tmp_path / "camchain.yaml"), "--camera", "cam1"
    )
    assert code == 0
    cam = tomllib.loads(stdout)["camera"]
    assert (cam["width"], cam["fx"], cam["distortion"]) == (
        752,
        457.5,
        [-0.28, 0.07, 0.0001, 0.0002, 0.0],
    )


@pytest.mark.parametrize(
    "name, write, model",
    [
        ("kalibr_equi.yaml", lambda p: _kalibr(p, distortion_model="equidistant"), "equidistant"),
        (
            "kalibr_omni.yaml",
            lambda p: _kalibr(p, camera_model="omni", intrinsics=(0.8, FX, FY, CX, CY)),
            "omni",
        ),
        (
            "ros_rational.yaml",
            lambda p: _ros(p, "rational_polynomial", DIST + [0.002, 0.0, 0.0]),
            "rational_polynomial",
        ),
        ("ros_fisheye.yaml", lambda p: _ros(p, "equidistant", DIST[:4]), "equidistant"),
        ("opencv_fisheye.yml", lambda p: _opencv(p, dist=DIST[:4], fisheye_model=1), "fisheye"),
        ("opencv_rational.xml", lambda p: _opencv(p, dist=DIST + [0.0, 0.01, 0.0]), "k5 = 0.01"),
    ],
)
def test_unsupported_models_are_one_line_errors(name, write, model, tmp_path, capsys):
    src = write(tmp_path / name)
    out = tmp_path / "cam.toml"
    code, _, stderr = _run(capsys, "calibrate", "import", src, "--out", out)
    assert code == 2
    assert stderr.count("\n") == 1
    assert str(src) in stderr and model in stderr
    assert not out.exists()


def test_import_never_overwrites_without_force(tmp_path, capsys):
    src = _ros(tmp_path / "ost.yaml")
    out = tmp_path / "cam.toml"
    out.write_text("# mine\n")
    code, _, stderr = _run(capsys, "calibrate", "import", src, "--out", out)
    assert code == 2 and stderr.count("\n") == 1 and out.read_text() == "# mine\n"
    code, _, _ = _run(capsys, "calibrate", "import", src, "--out", out, "--force")
    assert code == 0 and _read(out)[0] == EXPECTED


def test_import_rejects_what_is_not_a_calibration(tmp_path, capsys):
    src = tmp_path / "notes.yaml"
    src.write_text("title: field day\nsite: [lake]\n")
    code, _, stderr = _run(capsys, "calibrate", "import", src)
    assert code == 2 and stderr.count("\n") == 1 and str(src) in stderr
