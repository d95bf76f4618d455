"""Camera calibrations written by other tools, as skyfix's ``[camera]`` table.

Read formats:

- OpenCV ``cv2.FileStorage`` YAML (``%YAML:1.0``) or XML, with the names OpenCV's
  calibration samples write: ``camera_matrix``, ``distortion_coefficients``,
  ``image_width``, ``image_height`` (also ``cameraMatrix``/``dist_coeffs``/
  ``cameraResolution``); 4, 5, 8, 12 or 14 coefficients, the ones past k3 zero;
  ``fisheye_model: 1`` is refused.
- Kalibr camchain YAML: ``camN`` with ``camera_model: pinhole``, ``intrinsics: [fu, fv,
  pu, pv]``, ``distortion_model: radtan`` (``[k1, k2, r1, r2]``, k3 = 0) or ``none``,
  ``resolution: [w, h]``.
- ROS ``camera_info`` YAML as ``camera_calibration`` writes it (``image_width``,
  ``camera_matrix: {rows, cols, data}``, ``distortion_model``, ``distortion_coefficients``)
  or as ``ros2 topic echo`` prints the message (``width``, ``k``, ``d``);
  ``plumb_bob``, or ``rational_polynomial`` whose k4..k6 are zero.

All three use OpenCV's pixel convention (pixel (0, 0) is the centre of the top-left
pixel) and OpenCV's radial-tangential model, so the numbers carry over unchanged.
Every problem, an unsupported model included, is a one-line
:class:`~localizer.calibration.ConfigError` naming the file and the value.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import yaml

from groundstation.calibration.board import CalibrateError, camera_table
from localizer.camera import Camera
from localizer.contract import ConfigError, validate

_MODEL = (
    "skyfix's camera is a pinhole with OpenCV's radial-tangential distortion (k1, k2, p1, p2, k3)"
)
_EXTRA_NAMES = ("k4", "k5", "k6", "s1", "s2", "s3", "s4", "tau_x", "tau_y")


def _one_line(text) -> str:
    return " ".join(str(text).split())


def _numbers(src: str, key: str, value) -> np.ndarray:
    try:
        out = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(src, key, value, "expected numbers") from None
    if not np.all(np.isfinite(out)):
        raise ConfigError(src, key, out.tolist(), "must be finite")
    return out


def _intrinsics(src: str, key: str, K) -> tuple[float, float, float, float]:
    """fx, fy, cx, cy from a 3×3 matrix; skew and a non-standard last row are refused."""
    K = _numbers(src, key, K)
    if K.shape != (3, 3) and K.size == 9:
        K = K.reshape(3, 3)
    if K.shape != (3, 3):
        raise ConfigError(src, key, K.tolist(), "expected a 3x3 camera matrix")
    if abs(K[0, 1]) > 1e-9 * abs(K[0, 0]):
        raise ConfigError(
            src, f"{key}[0][1]", float(K[0, 1]), f"a skewed camera is not supported: {_MODEL}"
        )
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise ConfigError(src, key, K.tolist(), "expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
    return K[0, 0], K[1, 1], K[0, 2], K[1, 2]


def _distortion(src: str, key: str, coeffs, model: str) -> list[float]:
    """(k1, k2, p1, p2, k3) from OpenCV's 4, 5, 8, 12 or 14 coefficients; the rest must be zero."""
    d = [float(c) for c in _numbers(src, key, coeffs).ravel()]
    if len(d) not in (0, 4, 5, 8, 12, 14):
        raise ConfigError(src, key, d, "expected 4, 5, 8, 12 or 14 OpenCV distortion coefficients")
    extra = {n: v for n, v in zip(_EXTRA_NAMES, d[5:]) if v != 0}
    if extra:
        terms = ", ".join(f"{n} = {v:g}" for n, v in extra.items())
        raise ConfigError(src, key, d, f"{model} with nonzero {terms} is not supported: {_MODEL}")
    return (d + [0.0] * 5)[:5]


def _table(src: str, width, height, fx, fy, cx, cy, distortion) -> dict:
    for key, value in (("width", width), ("height", height)):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(src, key, value, "expected a whole number of pixels")
        if key == "width":
            width = value
        else:
            height = value
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=float)
    cam = camera_table(width, height, K, distortion)
    # the loader's own checks (positive focal lengths, principal point inside the image, ...)
    validate(Camera, cam, src, prefix="camera")
    return cam


def _from_filestorage(path: Path) -> tuple[dict, str]:
    src = str(path)
    try:
        fs = cv2.FileStorage(src, cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as e:
        cause = e.__cause__ if isinstance(e, SystemError) and e.__cause__ else e
        why = " ".join(str(getattr(cause, a, "")) for a in ("func", "err")).strip() or _one_line(
            cause
        )
        raise CalibrateError(f"{src}: OpenCV cannot parse it: {why}") from None
    if not fs.isOpened():
        raise CalibrateError(f"{src}: OpenCV cannot open it")

    def node(*names):
        for name in names:
            n = fs.getNode(name)
            if not n.empty():
                return name, n
        raise ConfigError(src, names[0], None, f"missing (looked for {', '.join(names)})")

    fisheye = fs.getNode("fisheye_model")
    if not fisheye.empty() and fisheye.real() != 0:
        raise ConfigError(
            src,
            "fisheye_model",
            int(fisheye.real()),
            f"fisheye calibrations are not supported: {_MODEL}",
        )
    kname, kn = node("camera_matrix", "cameraMatrix", "K")
    dname, dn = node("distortion_coefficients", "dist_coeffs", "distCoeffs", "D")
    K, D = kn.mat(), dn.mat()
    if K is None:
        raise ConfigError(src, kname, None, "expected a matrix")
    if D is None:
        raise ConfigError(src, dname, None, "expected a matrix")
    if not fs.getNode("image_width").empty():
        width, height = node("image_width")[1].real(), node("image_height")[1].real()
    else:
        _, res = node("image_width", "cameraResolution")
        size = [res.at(i).real() for i in range(res.size())] if res.isSeq() else res.mat()
        size = [] if size is None else np.asarray(size, dtype=float).ravel().tolist()
        if len(size) != 2:
            raise ConfigError(src, "cameraResolution", size, "expected [width, height]")
        width, height = size
    fx, fy, cx, cy = _intrinsics(src, kname, K)
    dist = _distortion(src, dname, D, "OpenCV's rational/thin-prism/tilted model")
    kind = "XML" if path.suffix.lower() == ".xml" else "YAML"
    return _table(src, width, height, fx, fy, cx, cy, dist), f"OpenCV FileStorage {kind}"


def _from_kalibr(src: str, doc: dict, camera: str | None) -> tuple[dict, str]:
    cams = sorted(k for k, v in doc.items() if isinstance(v, dict) and "intrinsics" in v)
    name = camera or cams[0]
    cam = doc.get(name)
    if not isinstance(cam, dict):
        raise ConfigError(
            src, "--camera", name, f"no such camera in the camchain (it has {', '.join(cams)})"
        )
    model = cam.get("camera_model")
    if model != "pinhole":
        raise ConfigError(src, f"{name}.camera_model", model, f"unsupported camera model: {_MODEL}")
    dmodel = cam.get("distortion_model", "none")
    coeffs = cam.get("distortion_coeffs", [])
    if dmodel not in ("radtan", "none"):
        raise ConfigError(
            src, f"{name}.distortion_model", dmodel, f"unsupported distortion model: {_MODEL}"
        )
    if dmodel == "radtan" and (not isinstance(coeffs, list) or len(coeffs) != 4):
        raise ConfigError(
            src, f"{name}.distortion_coeffs", coeffs, "expected [k1, k2, r1, r2] for radtan"
        )
    intr, res = cam.get("intrinsics"), cam.get("resolution")
    if not isinstance(intr, list) or len(intr) != 4:
        raise ConfigError(src, f"{name}.intrinsics", intr, "expected [fu, fv, pu, pv] for pinhole")
    if not isinstance(res, list) or len(res) != 2:
        raise ConfigError(src, f"{name}.resolution", res, "expected [width, height]")
    dist = (
        [*_numbers(src, f"{name}.distortion_coeffs", coeffs).tolist(), 0.0]
        if dmodel == "radtan"
        else [0.0] * 5
    )
    intr = _numbers(src, f"{name}.intrinsics", intr).tolist()
    note = (
        f"Kalibr camchain ({name}: pinhole, {dmodel}"
        + (f"; of {', '.join(cams)}" if len(cams) > 1 else "")
        + ")"
    )
    return _table(src, res[0], res[1], *intr, dist), note


def _ros_matrix(src: str, key: str, value):
    data = value.get("data") if isinstance(value, dict) else value
    if not isinstance(data, list):
        raise ConfigError(src, key, value, "expected {rows, cols, data: [...]} or a list")
    return data


def _from_ros(src: str, doc: dict) -> tuple[dict, str]:
    if "camera_matrix" in doc:  # camera_calibration's file
        wkey, hkey, kkey, dkey, form = (
            "image_width",
            "image_height",
            "camera_matrix",
            "distortion_coefficients",
            "file",
        )
    else:  # the CameraInfo message as echoed (ROS 2: k, d; ROS 1: K, D)
        wkey, hkey, form = "width", "height", "message"
        kkey, dkey = ("k", "d") if "k" in doc else ("K", "D")
    model = doc.get("distortion_model", "plumb_bob")
    if model not in ("plumb_bob", "rational_polynomial"):
        raise ConfigError(src, "distortion_model", model, f"unsupported distortion model: {_MODEL}")
    K = _ros_matrix(src, kkey, doc.get(kkey))
    D = _ros_matrix(src, dkey, doc.get(dkey, []))
    fx, fy, cx, cy = _intrinsics(src, kkey, K)
    dist = _distortion(src, dkey, D, model)
    if wkey not in doc or hkey not in doc:
        raise ConfigError(src, wkey if wkey not in doc else hkey, None, "missing")
    return _table(
        src, doc[wkey], doc[hkey], fx, fy, cx, cy, dist
    ), f"ROS camera_info {form} ({model})"


def import_calibration(path, camera: str | None = None) -> tuple[dict, str]:
    """``([camera] table, a note on the format read)`` from an OpenCV, Kalibr or ROS file."""
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text(errors="replace")
    except OSError as e:
        raise CalibrateError(f"{src}: cannot read: {e.strerror or e}") from None
    head = text.lstrip()
    if (
        path.suffix.lower() == ".xml"
        or head.startswith(("<?xml", "%YAML:"))
        or "!!opencv-matrix" in text
    ):
        return _from_filestorage(path)
    try:
        docs = [d for d in yaml.safe_load_all(text) if d is not None]
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise CalibrateError(
            f"{src}: malformed YAML: {where}{_one_line(getattr(e, 'problem', None) or e)}"
        ) from None
    doc = docs[0] if docs else None
    if isinstance(doc, dict) and any(
        isinstance(v, dict) and "intrinsics" in v for v in doc.values()
    ):
        return _from_kalibr(src, doc, camera)
    if isinstance(doc, dict) and any(k in doc for k in ("camera_matrix", "k", "K")):
        return _from_ros(src, doc)
    raise CalibrateError(
        f"{src}: not a calibration skyfix reads (OpenCV FileStorage YAML/XML, Kalibr camchain, ROS camera_info)"
    )
