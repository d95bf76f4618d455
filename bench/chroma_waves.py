"""How a UUV seen through rendered wind waves stands out of the seafloor in the decoder's planes (issue 28).

    .venv/bin/python bench/chroma_waves.py [--work /tmp/skyfix-tracker-waves] [--only NAME ...]
                                           [--out bench/results/tracker_waves_chroma.txt]

Reads the sessions :mod:`tracker_waves` renders (``--work``, the same conditions; not rendered here) as the tracker
reads a video: the yuv420p frames' planes as decoded (luma Y; chroma U, V at half its size each way). Per visible
frame, at the UUV's true pixel (``track.csv``), and per hidden frame, at its last visible one (where a tracker's
prediction holds it), each measure's *distinctness*: its best value over the UUV-sized squares (side
:data:`BOX_SHARE` of the UUV's size) within :data:`REACH_SHARE` of its size of that place, over the 90th percentile
of the squares' values beyond :data:`FLOOR_SHARE` of its size about the best (the seafloor beside it). A measure that
tells the UUV from the seafloor is high on every visible frame and low on every hidden one: the table gives the 5th
and 10th percentile over the visible frames and the highest and 95th percentile over the hidden ones.

- ``grey spread``: the luma's standard deviation in the square (what the tracker's contrast reads; whichever way
  the vehicle departs from the seafloor);
- ``hue``: the chroma's mean departure from the seafloor's (the squares' median) in the direction of the vehicle's
  departure on the first frame (a hue that stays while the light changes);
- ``chroma spread``: the standard deviation in the square of the chroma channel that tells the first frame's vehicle
  from the seafloor about it best (Fisher's discriminant over U and V; whichever way).

``flipped``: the share of the visible frames where the vehicle's luma departs from the seafloor's the other way
than on the first frame (its square's mean less the squares' median): the caustics' flip that breaks a
grey-level template.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import av
import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from emit import emit
from tracker_waves import CONDITIONS, first_size_px

from groundstation.session.read import read_table
from groundstation.video.frames import plane_array

BOX_SHARE = 0.7  # the squares' side, of the UUV's size
REACH_SHARE = 0.3  # the best square within this much of the UUV's size of the place
FLOOR_SHARE = 0.75  # the seafloor's squares beyond this much of its size about the best
MEASURES = ("grey spread", "hue", "chroma spread")


def _odd(x: float) -> int:
    return max(3, round(x)) | 1


def _square(plane: np.ndarray, x: int, y: int, half: int) -> np.ndarray | None:
    if x - half < 0 or y - half < 0 or x + half >= plane.shape[1] or y + half >= plane.shape[0]:
        return None
    return plane[y - half : y + half + 1, x - half : x + half + 1].astype(np.float64)


def _spread(level: np.ndarray, box: int) -> np.ndarray:
    mean, square = cv2.blur(level, (box, box)), cv2.blur(level * level, (box, box))
    return np.sqrt(np.maximum(square - mean * mean, 0.0))


def distinct(values: np.ndarray, reach: int, box: int, floor: int) -> float:
    """The best of ``values`` (a map centred on the place) within ``reach`` of its centre over the 90th percentile
    of its values beyond ``floor`` of the best (and ``box`` // 2 in from its edges)."""
    half = values.shape[0] // 2
    _, best, _, (j, i) = cv2.minMaxLoc(
        values[half - reach : half + reach + 1, half - reach : half + reach + 1]
    )
    pj, pi, edge = half - reach + j, half - reach + i, box // 2
    mask = np.zeros(values.shape, bool)
    mask[edge:-edge, edge:-edge] = True
    mask[max(pi - floor, 0) : pi + floor + 1, max(pj - floor, 0) : pj + floor + 1] = False
    return best / max(float(np.percentile(values[mask], 90)), 1e-9)


def fisher(pixels: np.ndarray, inner: slice, ring: np.ndarray) -> np.ndarray:
    """The weights of the channel in which ``pixels``' square ``inner`` stands out most from ``ring`` (Fisher's
    discriminant, a level of variance 1 added), norm 1."""
    inside = pixels[inner, inner].reshape(-1, pixels.shape[-1])
    outside = pixels[ring]
    pooled = np.cov(inside.T) + np.cov(outside.T) + np.eye(pixels.shape[-1])
    w = np.linalg.solve(pooled, inside.mean(axis=0) - outside.mean(axis=0))
    return w / np.linalg.norm(w)


def condition(session: Path) -> dict:
    """Per measure, the distinctness over the visible and the hidden frames, and the flipped share."""
    truth = read_table(session / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    size = first_size_px(session)
    out = {m: ([], []) for m in MEASURES}
    signs, first, hue, weights, last = [], None, None, None, None
    with av.open(str(session / "video.mp4")) as container:
        for i, frame in enumerate(container.decode(video=0)):
            visible = bool(np.isfinite(truth["u"][i]))
            if visible:
                last = (truth["u"][i], truth["v"][i])
            if last is None:
                continue
            u, v = last
            planes = [plane_array(p) for p in frame.planes]
            for name, scale, level in _levels(planes, size, hue, weights, u, v):
                box, reach = (
                    _odd(BOX_SHARE * size / scale),
                    max(1, round(REACH_SHARE * size / scale)),
                )
                floor = round(FLOOR_SHARE * size / scale)
                half = reach + floor + box
                x, y = round((u - (scale - 1) / 2) / scale), round((v - (scale - 1) / 2) / scale)
                square = _square(level, x, y, half)
                if square is None:
                    continue
                values = (
                    cv2.blur(square - np.median(square), (box, box))
                    if name == "hue"
                    else _spread(square, box)
                )
                out[name][0 if visible else 1].append(distinct(values, reach, box, floor))
            x, y, half, b = round(u), round(v), round(size), _odd(BOX_SHARE * size) // 2
            grey = _square(planes[0], x, y, half)
            if grey is not None and visible:
                departs = float(
                    grey[half - b : half + b + 1, half - b : half + b + 1].mean()
                ) - float(np.median(grey))
                first = departs if first is None else first
                signs.append(np.sign(departs) != np.sign(first))
            if hue is None:
                hue, weights = _first_hue(planes, size, u, v)
    row = {"flipped": float(np.mean(signs))}
    for name, (seen, hidden) in out.items():
        row[name] = (
            *np.percentile(seen, (5, 10)),
            max(hidden) if hidden else math.nan,
            float(np.percentile(hidden, 95)) if hidden else math.nan,
        )
    return row


def _first_hue(planes, size: float, u: float, v: float):
    """The vehicle's hue on the first frame: its chroma square's mean departure from the seafloor's median about it
    (U, V; norm 1), and the Fisher weights of the chroma channel it stands out in most."""
    x, y, side = round((u - 0.5) / 2), round((v - 0.5) / 2), round(size / 2)
    b = _odd(BOX_SHARE * size / 2) // 2
    pixels = np.stack([_square(p, x, y, side) for p in planes[1:]], axis=-1)
    inner = slice(side - b, side + b + 1)
    ring = np.ones(pixels.shape[:2], bool)
    ring[side - side // 2 : side + side // 2 + 1, side - side // 2 : side + side // 2 + 1] = False
    hue = pixels[inner, inner].reshape(-1, 2).mean(axis=0) - np.median(
        pixels.reshape(-1, 2), axis=0
    )
    return hue / np.linalg.norm(hue), fisher(pixels, inner, ring)


def _levels(planes, size, hue, weights, u, v):
    """(measure, the plane's step in pixels, its level) for each measure (the chroma ones once the first frame's
    hue is known)."""
    yield "grey spread", 1, planes[0].astype(np.float64)
    if hue is None:
        return
    cu, cv_ = (p.astype(np.float64) for p in planes[1:])
    yield "hue", 2, hue[0] * cu + hue[1] * cv_
    yield "chroma spread", 2, weights[0] * cu + weights[1] * cv_


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/skyfix-tracker-waves")
    ap.add_argument("--only", nargs="*", help="condition names")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "tracker_waves_chroma.txt"))
    args = ap.parse_args()
    load0 = os.getloadavg()
    lines = [
        "distinctness of the UUV's square over the seafloor's (90th percentile): visible frames p5/p10 (high: it",
        "stands out), hidden frames max/p95 (low: nothing there); flipped: visible frames whose luma departs the",
        "other way than on the first frame",
        f"{'condition':14} {'flipped':>7} " + " ".join(f"{m:>27}" for m in MEASURES),
    ]
    for name, *_ in CONDITIONS:
        if args.only and name not in args.only:
            continue
        session = Path(args.work) / name
        if not (session / "video.mp4").exists():
            print(
                f"{name}: not rendered in {args.work} (bench/tracker_waves.py renders it)",
                file=sys.stderr,
            )
            continue
        row = condition(session)
        cells = " ".join(
            "{:5.2f} {:5.2f} / {:6.2f} {:5.2f}".format(*row[m]).rjust(27) for m in MEASURES
        )
        lines.append(f"{name:14} {row['flipped']:7.1%} {cells}")
        print(lines[-1], file=sys.stderr, flush=True)
    load1 = os.getloadavg()
    lines.append(
        "\nload average (1, 5, 15 min): {:.2f} {:.2f} {:.2f} at the start, {:.2f} {:.2f} {:.2f} at the end".format(
            *load0, *load1
        )
    )
    emit(lines, Path(args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
