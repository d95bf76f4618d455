"""``skyfix calibrate``: the camera's ``[camera]`` table (intrinsics and distortion) for session.toml.

``skyfix calibrate camera INPUT --board chessboard|charuco --cols N --rows M --square-m S --out FILE``
calibrates from a video or a folder of images of a calibration board;
``skyfix calibrate import FILE`` converts a calibration made with OpenCV, Kalibr or ROS.

Calibrate in air, never through water. The UAV's camera looks through air down to the
water surface, and skyfix's geometry bends each ray there by Snell's law itself. A
calibration made through water (the board underwater, or the camera behind a port)
folds the refraction into the focal length and distortion, and skyfix would then
refract twice.

Calibrate the camera as it flies: the same video mode (resolution and crop: a drone's
photo and video modes often differ), the same zoom, focus locked where it will be
(at infinity for a UAV at altitude), the same in-camera lens-correction setting. Fill
the image with board views at varied tilts, and reach the image's corners: the
coverage report shows where the board's corners were seen; where they were not,
the distortion is extrapolated.

The model is pinhole with OpenCV's radial-tangential distortion (k1, k2, p1, p2, k3),
pixel (0, 0) the centre of the top-left pixel. The output file holds ``[camera]`` and,
as TOML comments, the RMS reprojection error, the number of views used and the
parameters' standard deviations; paste ``[camera]`` into session.toml or the
``--calibration`` file next to ``[mount]`` and ``[water]``. An existing output file is
never overwritten without ``--force``.
"""

from __future__ import annotations

import math
import sys
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

from groundstation.calibration import board as cb
from groundstation.calibration.board import Board, CalibrateError, Detector, View
from groundstation.calibration.formats import import_calibration
from groundstation.video.file import open_video
from groundstation.video.frames import VideoError
from localizer.camera import Camera
from localizer.contract import ConfigError, validate

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
IN_AIR = (
    "Calibrated in air: the camera looks through air to the water surface; skyfix's geometry\n"
    "refracts each ray there, so this table must not include water's refraction."
)


def _float(v: float) -> str:
    """A TOML float, 10 significant digits."""
    s = f"{v:.10g}"
    return s if any(c in s for c in ".en") else s + ".0"


def camera_toml(cam: dict, comments: list[str]) -> str:
    """``[camera]`` as TOML, after ``comments`` (each becomes a ``#`` line)."""
    lines = [f"# {line}".rstrip() for c in comments for line in c.split("\n")]
    lines += [
        "",
        "[camera]",
        f"width = {cam['width']}",
        f"height = {cam['height']}",
        *(f"{k} = {_float(cam[k])}" for k in ("fx", "fy", "cx", "cy")),
        f"distortion = [{', '.join(_float(d) for d in cam['distortion'])}]   # k1, k2, p1, p2, k3",
    ]
    return "\n".join(lines) + "\n"


def _check_out(out: str | None, force: bool) -> None:
    if out and Path(out).exists() and not force:
        raise CalibrateError(f"{out}: exists; not overwritten without --force")


def _write(out: str, text: str) -> None:
    path = Path(out)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text)
        tmp.replace(path)
    except OSError as e:
        raise CalibrateError(f"{out}: cannot write: {e.strerror or e}") from None


# --- skyfix calibrate camera ------------------------------------------------------------


def _board(args) -> Board:
    for key, value, least in (("--cols", args.cols, 3), ("--rows", args.rows, 3)):
        if args.board == "chessboard":
            least = 4  # OpenCV needs at least 3 inner corners each way
        if value < least:
            raise ConfigError(
                "options", key, value, f"a {args.board} needs at least {least} squares"
            )
    if not args.square_m > 0:
        raise ConfigError(
            "options", "--square-m", args.square_m, "must be > 0 (the square's side in metres)"
        )
    if args.board == "chessboard":
        return Board("chessboard", args.cols, args.rows, args.square_m)
    if args.marker_m is None:
        raise ConfigError(
            "options",
            "--marker-m",
            None,
            "required for a ChArUco board (the marker's side in metres)",
        )
    if not 0 < args.marker_m < args.square_m:
        raise ConfigError(
            "options",
            "--marker-m",
            args.marker_m,
            f"must be > 0 and < --square-m {args.square_m:g}",
        )
    if not args.dict.startswith("DICT_") or not hasattr(cv2.aruco, args.dict):
        names = ", ".join(n for n in dir(cv2.aruco) if n.startswith("DICT_") and n == n.upper())
        raise ConfigError("options", "--dict", args.dict, f"expected one of {names}")
    return Board(
        "charuco", args.cols, args.rows, args.square_m, args.marker_m, args.dict, args.legacy
    )


def _frames(src: Path, every: int | None, max_frames: int):
    """``(name, grey image)`` of the images of a folder or the sampled frames of a video."""
    if src.is_dir():
        files = sorted(p for p in src.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise CalibrateError(f"{src}: no images ({', '.join(IMAGE_SUFFIXES)})")
        step = every or max(1, math.ceil(len(files) / max_frames))
        for p in files[::step]:
            img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise CalibrateError(f"{p}: not an image OpenCV can read")
            yield p.name, img
        return
    with open_video(src) as video:
        count = video.frame_count
        step = every or (max(1, math.ceil(count / max_frames)) if count > 0 else 10)
        limit = max_frames if every is None else math.inf
        taken = 0
        for frame in video:
            if taken >= limit:
                break
            if frame.index % step == 0:
                taken += 1
                yield f"frame {frame.index}", cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY)


def _names(names: list[str], n: int = 8) -> str:
    return ", ".join(names[:n]) + (f" and {len(names) - n} more" if len(names) > n else "")


def run_camera(args) -> int:
    _check_out(args.out, args.force)
    board = _board(args)
    src = Path(args.input)
    if not src.exists():
        raise CalibrateError(f"{src}: missing")
    if args.every is not None and args.every < 1:
        raise ConfigError("options", "--every", args.every, "must be ≥ 1")
    if args.max_frames < 4:
        raise ConfigError("options", "--max-frames", args.max_frames, "must be ≥ 4")
    detector = Detector(board)
    views: list[View] = []
    missed: list[str] = []
    size = None
    for name, gray in _frames(src, args.every, args.max_frames):
        h, w = gray.shape[:2]
        if size is None:
            size = (w, h)
        elif (w, h) != size:
            where = f"{src / name}:" if src.is_dir() else f"{src}: {name} is"
            raise CalibrateError(f"{where} {w}x{h} pixels, the first one {size[0]}x{size[1]}")
        found = detector.detect(gray)
        if found is None:
            missed.append(name)
        else:
            views.append(View(name, *found))
    seen = len(views) + len(missed)
    if len(views) < 4:
        raise CalibrateError(
            f"{src}: the {board.describe()} was found in {len(views)} of {seen} "
            f"{'images' if src.is_dir() else 'frames'}; calibration needs at least 4 views "
            "(--cols/--rows count squares, not inner corners; check --board and --dict)"
        )
    print(
        f"{board.describe()}: found in {len(views)} of {seen} {'images' if src.is_dir() else 'frames'} of {src}"
        + (f" (not in {_names(missed)})" if missed else "")
    )
    res = cb.calibrate(views, size, fix_k3=args.fix_k3)
    cam = res.camera
    validate(Camera, cam, str(src), prefix="camera")
    cov = cb.coverage(res.views, res.width, res.height, cam["cx"], cam["cy"])

    report = []
    if res.dropped:
        report.append(
            f"dropped {len(res.dropped)} view(s) as outliers (RMS above {res.limit_px:.3g} px): "
            + ", ".join(f"{n} {e:.3g} px" for n, e in res.dropped)
        )
    report.append(
        f"camera {res.width}x{res.height} from {len(res.views)} views: RMS reprojection error "
        f"{res.rms_px:.3g} px (per view: median {np.median(res.view_rms_px):.3g}, "
        f"max {np.max(res.view_rms_px):.3g})"
    )
    values = dict(zip(cb.PARAMS, [cam["fx"], cam["fy"], cam["cx"], cam["cy"], *cam["distortion"]]))
    report.append(
        "  "
        + "   ".join(f"{k} = {values[k]:.6g} ± {res.std[k]:.2g}" for k in cb.PARAMS[:4])
        + "  (px)"
    )
    report.append(
        "  "
        + "   ".join(f"{k} = {values[k]:.6g} ± {res.std[k]:.2g}" for k in cb.PARAMS[4:])
        + ("  (k3 fixed at 0)" if args.fix_k3 else "")
    )
    report += cov.lines(res.width, res.height)
    print("\n".join(report))

    warnings = []
    if cov.uncovered_corners:
        c = cov.uncovered_corners
        which = (
            f"{c[0]} corner was" if len(c) == 1 else f"{', '.join(c[:-1])} and {c[-1]} corners were"
        )
        warnings.append(
            f"the image's {which} never covered by the board: distortion there is extrapolated; "
            "add views with the board in the image's corners (or use --fix-k3)"
        )
    if len(res.views) < cb.FEW_VIEWS:
        warnings.append(
            f"only {len(res.views)} views used; 15-40 at varied tilts give a dependable calibration"
        )
    if res.rms_px > 1.0:
        warnings.append(
            f"RMS reprojection error {res.rms_px:.3g} px is high: check --square-m, --cols/--rows, "
            "focus and motion blur"
        )
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)

    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    comments = [
        f"Camera calibration by `skyfix calibrate camera` (OpenCV {cv2.__version__}), {when}",
        f"input: {src}, {seen} {'images' if src.is_dir() else 'frames'} examined",
        f"board: {board.describe()}",
        f"views: {len(res.views)} used of {seen}; no board in {len(missed)}; {len(res.dropped)} dropped as outliers"
        + (f" ({_names([n for n, _ in res.dropped])})" if res.dropped else ""),
        IN_AIR,
        "Paste [camera] into session.toml or the --calibration file, next to [mount] and [water].",
        "",
        "Quality, as TOML comments (skyfix reads only [camera]); std_* are 1-sigma (cv2.calibrateCameraExtended):",
        f"rms_px = {res.rms_px:.4g}",
        f"views_used = {len(res.views)}",
        *(f"std_{k} = {res.std[k]:.3g}" for k in cb.PARAMS),
        f"coverage = {[[int(c) for c in row] for row in cov.counts]}   # corners per cell, 4x4 grid, top row first",
        *(f"WARNING: {w}" for w in warnings),
    ]
    _write(args.out, camera_toml(cam, comments))
    print(f"-> {args.out}")
    return 0


# --- skyfix calibrate import ------------------------------------------------------------


def run_import(args) -> int:
    _check_out(args.out, args.force)
    cam, kind = import_calibration(args.file, camera=args.camera)
    comments = [
        f"Camera calibration imported by `skyfix calibrate import` from {args.file}",
        f"format: {kind}",
        IN_AIR,
        "Paste [camera] into session.toml or the --calibration file, next to [mount] and [water].",
    ]
    text = camera_toml(cam, comments)
    if args.out:
        _write(args.out, text)
        print(f"{args.file} ({kind}) -> {args.out}")
    else:
        sys.stdout.write(text)
    return 0


def run(args) -> int:
    try:
        return args.calibrate_func(args)
    except (CalibrateError, VideoError) as e:
        print(f"skyfix calibrate: error: {e}", file=sys.stderr)
        return 2


_AIR_HELP = (
    "Calibrate in air: the camera looks through air to the water surface and skyfix's geometry "
    "handles the refraction there. Do not calibrate through water (board underwater or camera "
    "behind a port): refraction would be folded into the calibration and applied twice."
)


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(
        name,
        help=help,
        description="The camera's [camera] table for session.toml. " + _AIR_HELP,
    )
    sub = p.add_subparsers(dest="calibrate_command", required=True)

    c = sub.add_parser(
        "camera",
        help="calibrate from a video or a folder of images of a chessboard or ChArUco board",
        description=(
            "Detect the board, calibrate with OpenCV (pinhole, radial-tangential k1, k2, p1, p2, k3), drop "
            "views whose RMS reprojection error is far above the rest and recalibrate, print where in the "
            "image the board's corners were seen, and write [camera] (with the RMS error, views used and "
            "1-sigma parameter uncertainties as comments). "
            + _AIR_HELP
            + " Use the video mode, zoom and "
            "focus you fly with, and bring the board into the image's corners."
        ),
    )
    c.add_argument("input", help="a video file, or a folder of images (.png, .jpg, ...)")
    c.add_argument("--board", required=True, choices=("chessboard", "charuco"))
    c.add_argument(
        "--cols",
        type=int,
        required=True,
        help="squares along the board's width (a chessboard of 10x7 squares has 9x6 inner corners)",
    )
    c.add_argument("--rows", type=int, required=True, help="squares along the board's height")
    c.add_argument(
        "--square-m",
        type=float,
        required=True,
        help="side of one square, metres (measure the print)",
    )
    c.add_argument("--marker-m", type=float, help="ChArUco: side of one ArUco marker, metres")
    c.add_argument(
        "--dict",
        default="DICT_5X5_100",
        help="ChArUco: the ArUco dictionary (default DICT_5X5_100)",
    )
    c.add_argument(
        "--legacy",
        action="store_true",
        help="ChArUco: a board generated by OpenCV < 4.6 (differs when --rows is even)",
    )
    c.add_argument(
        "--every",
        type=int,
        help="use every N-th frame or image (default: evenly up to --max-frames)",
    )
    c.add_argument(
        "--max-frames",
        type=int,
        default=100,
        help="frames (images) examined at most, evenly spaced (default 100)",
    )
    c.add_argument(
        "--fix-k3",
        action="store_true",
        help="keep k3 at 0 (narrow lenses, or when the board never reached the image's corners)",
    )
    c.add_argument("--out", required=True, help="the TOML file to write")
    c.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    c.set_defaults(func=run, calibrate_func=run_camera)

    i = sub.add_parser(
        "import",
        help="convert an OpenCV (YAML/XML), Kalibr camchain or ROS camera_info calibration",
        description=(
            "Read a calibration made elsewhere: OpenCV cv2.FileStorage YAML/XML (camera_matrix, "
            "distortion_coefficients, image_width, image_height), a Kalibr camchain (pinhole, radtan) or a "
            "ROS camera_info YAML (plumb_bob), and write skyfix's [camera] table. Other models (fisheye, "
            "equidistant, omni, rational_polynomial with nonzero k4..k6) are refused. " + _AIR_HELP
        ),
    )
    i.add_argument("file", help="the calibration file")
    i.add_argument("--camera", help="Kalibr: which camera of the camchain (default cam0)")
    i.add_argument("--out", help="the TOML file to write (default: print it)")
    i.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    i.set_defaults(func=run, calibrate_func=run_import)
