"""Whether the check of an operator's box (and of ``[tracker] init_bbox`` live) tells the UUV from the seafloor in waves.

    .venv/bin/python bench/box_check_waves.py [--work /tmp/h1-waves] [--out bench/results/box_check_waves.txt]

Live, a box is taken only where :func:`localizer.tracking.detect.detect` finds a vehicle-sized object standing out
of the water in it (``TrackingSession.select(..., verify=True)``, the live pipeline's check): the best place's
saliency (its deviation energy over the window's median) at least ``min_saliency`` and ``distinct`` times the best
elsewhere. For each session (bench/tracker_waves.py's rendered wave conditions in ``--work``, and the bundled flat
ones), on frames 0, 60 and 150, with the camera's pose of the frame:

- ``vehicle``: the box of ``init_bbox``'s size centred on the UUV's true pixel (track.csv) as the live check takes
  it: ``kept``/``snapped`` or ``refused``, and the saliency detect finds there with no floor (``-``: none distinct);
- ``seafloor``: the same box moved 2, 3 and 4.5 box sizes away in 8 directions (inside the frame): how many the
  check takes on something other than the UUV (a box on the seafloor tracked as the UUV), and the saliencies of the
  places detect finds distinct there with no floor (their largest): what a floor would have to stay above.
- ``steady``: the same boxes checked over frames as the live pipeline now checks them
  (``TrackingSession.select(..., steady=True)``: followed from that frame for ``STEADY_S``, taken when a vehicle
  stands out of the mean of its window's saliencies): the vehicle's box kept/snapped/refused, and how many seafloor
  boxes it takes on something other than the UUV (the taken box's centre further than the box's size from the
  UUV's true pixel in the frame the check ends on). The frames' colour is given as the live pipeline gives it (from
  the BGR frame; with ``--luma`` the decoded chroma planes).
- ``colour when drawn``: how far each box stands out of its surroundings in colour when drawn, as the check over
  frames learns it (:func:`localizer.tracking.colour.learn`): the UUV's boxes and the seafloor's against
  ``STEADY_COLOUR_MIN``, the least a box's colour takes it by.

``--luma``: the frames' luma planes, as the live pipeline's default tracker reads them (and checks the boxes on),
instead of BGR.

``--follow``: also each box taken unchecked (as ``select`` without ``verify``) on frames 0 and 60 of the wave
conditions and followed for :data:`FOLLOW` frames by the default tracker: of the UUV's box and of the seafloor
boxes 2 and 3 sizes away (those the tracker did not carry onto the UUV), the frames reported ``ok``, the median of
the matcher's ``distinct`` and the share of frames it reaches ``SURE_DISTINCT`` (the offline pass's "stands out"):
whether following a box for a second would tell the UUV from the seafloor where one frame does not.
"""

from __future__ import annotations

import argparse
import math
import os
import tomllib
from pathlib import Path

import av
import numpy as np
from emit import emit

from groundstation.offline.track import SURE_DISTINCT
from groundstation.session.read import load_session
from groundstation.video.frames import chroma_planes
from localizer.fix import locate
from localizer.pose import camera_pose, take
from localizer.tracking import Prediction
from localizer.tracking.colour import Chroma, learn
from localizer.tracking.detect import DetectParams, detect
from localizer.tracking.predict import prediction_at, project_uuv
from localizer.tracking.session import (
    STEADY_COLOUR_MIN,
    STEADY_S,
    SelectionError,
    TrackingSession,
)

ROOT = Path(__file__).resolve().parents[1]
FRAMES = (0, 60, 150)
STEPS = (2.0, 3.0, 4.5)  # box sizes away from the UUV
NO_FLOOR = DetectParams(min_saliency=0.0)
FOLLOW = 30  # frames a box taken unchecked is followed (--follow)
STEADY_FRAMES = 40  # frames read after each of FRAMES for the check over frames (at most 2 x STEADY_S at 30 fps)


def images(video: Path, picks, luma: bool = False) -> tuple[dict, dict]:
    """The frames ``picks`` (indices in decoding order) of ``video`` as BGR (``luma``: their luma planes), and their
    colour as the live pipeline gives it (the BGR frame's; with ``luma`` the decoded chroma planes)."""
    out, colours = {}, {}
    with av.open(str(video)) as container:
        for i, frame in enumerate(container.decode(video=0)):
            if i in picks:
                out[i] = frame.to_ndarray(format="gray" if luma else "bgr24")
                colours[i] = chroma_planes(frame).copy() if luma else Chroma.of(out[i])
            if i >= max(picks):
                break
    return out, colours


def checked(session, image, pose, i: int, box) -> tuple[str, tuple[float, float] | None]:
    """What the live check makes of ``box`` in frame ``i``: (kept/snapped/refused, the taken box's centre)."""
    tracking = TrackingSession(session.calibration, "default")
    try:
        result = tracking.select(image, pose, i, box=box, verify=True, keep_drawn=True)
    except SelectionError:
        return "refused", None
    return ("snapped" if tracking.outlined else "kept"), (result.u, result.v)


def checked_steady(
    session, frames: dict, colours: dict, pose, i: int, box
) -> tuple[str, tuple[float, float] | None, int]:
    """What the check over frames makes of ``box`` drawn on frame ``i``: (kept/snapped/refused, the taken box's
    centre, the frame the check ended on)."""
    tracking = TrackingSession(session.calibration, "default")
    tracking.select(
        frames[i],
        pose,
        i,
        box=box,
        verify=True,
        keep_drawn=True,
        steady=True,
        chroma=colours[i],
    )
    j = i
    while tracking.check == "confirming" and j + 1 in frames:
        j += 1
        result = tracking.step(frames[j], pose, j, chroma=colours[j])
    word = tracking.check.split(":")[0]
    return word, ((result.u, result.v) if word in ("kept", "snapped") else None), j


def saliency(
    image, pose, i: int, session, u: float, v: float, box
) -> tuple[float | None, float, float]:
    """(saliency, u, v) of the place detect finds distinct in ``box`` centred at (u, v) with no floor, sized by the
    frame's pose as the check sizes it ((None, nan, nan): none)."""
    one = take(pose, [i])
    fix = locate(session.calibration, one, [u], [v])
    if fix.status[0] != "ok":
        return None, math.nan, math.nan
    _, _, px_per_m = project_uuv(session.calibration, one, fix.lat[0], fix.lon[0])
    guess = prediction_at(u, v, float(px_per_m[0]), 0.0)
    if guess is None:
        return None, math.nan, math.nan
    reach = math.hypot(box[2], box[3]) / 2.0 / NO_FLOOR.search_sigmas
    found = detect(
        image,
        Prediction(u, v, guess.width_px, guess.height_px, reach, float(px_per_m[0])),
        NO_FLOOR,
    )
    return (None, math.nan, math.nan) if found is None else (found.saliency, found.u, found.v)


def colour_drawn(chroma: Chroma, u: float, v: float, box) -> float:
    """How far the box centred at (u, v) stands out of its surroundings in colour, as the check over frames learns
    it when the box is drawn (:func:`localizer.tracking.colour.learn`, ring spreads; NaN: not read)."""
    model = learn(chroma, u, v, max(box[2:]) / 2, min_separation=-math.inf)
    return math.nan if model is None else model.separation


def followed(path: Path, start: int) -> dict:
    """The UUV's box and the seafloor boxes of frame ``start`` taken unchecked and followed :data:`FOLLOW` frames."""
    session = load_session(path)
    w, h = tomllib.loads((path / "session.toml").read_text())["tracker"]["init_bbox"][2:]
    truth = np.genfromtxt(path / "track.csv", delimiter=",", names=True)
    pose = camera_pose(session.calibration, session.telemetry, session.frames["t"])
    frames, _ = images(session.video_path, set(range(start, start + FOLLOW + 1)))
    u, v = float(truth["u"][start]), float(truth["v"][start])
    H, W = frames[start].shape[:2]
    out = {"session": path.name, "frame": start, "uuv": None, "seafloor": []}
    for k, a in [(0.0, 0)] + [(k, a) for k in STEPS[:2] for a in range(8)]:
        cu, cv_ = u + k * w * math.cos(a * math.pi / 4), v + k * h * math.sin(a * math.pi / 4)
        if not (w < cu < W - w and h < cv_ < H - h):
            continue
        tracking = TrackingSession(session.calibration, "default")
        tracking.select(
            frames[start], pose, start, box=[round(cu - w / 2), round(cv_ - h / 2), w, h]
        )
        ok, on_uuv, distinct = 0, 0, []
        for j in range(start + 1, start + FOLLOW + 1):
            result = tracking.step(frames[j], pose, j)
            distinct.append(tracking.target.distinct)
            ok += result.ok
            near = math.hypot(result.u - truth["u"][j], result.v - truth["v"][j]) < max(w, h) / 2
            on_uuv += bool(result.ok and near)
        d = np.array(distinct, float)
        seen = d[np.isfinite(d)]
        row = {
            "ok": ok,
            "on_uuv": on_uuv,
            "distinct_median": float(np.median(seen)) if seen.size else math.nan,
            "sure_share": float(np.mean(seen >= SURE_DISTINCT)) if seen.size else 0.0,
        }
        if k == 0:
            out["uuv"] = row
        elif on_uuv < FOLLOW // 6:  # carried onto the UUV: not a seafloor box any more
            out["seafloor"].append(row)
    return out


def run(path: Path, luma: bool = False) -> dict:
    """Per frame: the vehicle's box checked (on one frame, over frames) and its saliency; the seafloor boxes taken
    (by each check) and their saliencies."""
    session = load_session(path)
    w, h = tomllib.loads((path / "session.toml").read_text())["tracker"]["init_bbox"][2:]
    truth = np.genfromtxt(path / "track.csv", delimiter=",", names=True)
    t = session.frames["t"]
    pose = camera_pose(session.calibration, session.telemetry, t)
    rows = []
    frames, colours = images(
        session.video_path,
        {j for i in FRAMES for j in range(i, min(i + STEADY_FRAMES, len(t)))},
        luma,
    )
    for i in FRAMES:
        image = frames[i]
        H, W = image.shape[:2]
        u, v = float(truth["u"][i]), float(truth["v"][i])
        if not (math.isfinite(u) and math.isfinite(v)):  # the UUV hidden in this frame
            continue
        box = [round(u - w / 2), round(v - h / 2), w, h]
        word, _ = checked(session, image, pose, i, box)
        steady, _, _ = checked_steady(session, frames, colours, pose, i, box)
        s, _, _ = saliency(image, pose, i, session, u, v, box)
        taken, steady_taken, distinct, drawn = 0, 0, [], []
        for k in STEPS:
            for a in range(8):
                cu = u + k * w * math.cos(a * math.pi / 4)
                cv_ = v + k * h * math.sin(a * math.pi / 4)
                if not (w < cu < W - w and h < cv_ < H - h):
                    continue
                sea = [round(cu - w / 2), round(cv_ - h / 2), w, h]
                what, at = checked(session, image, pose, i, sea)
                if what != "refused" and math.hypot(at[0] - u, at[1] - v) > max(w, h):
                    taken += 1
                what, at, j = checked_steady(session, frames, colours, pose, i, sea)
                if what != "refused" and not (
                    math.hypot(at[0] - truth["u"][j], at[1] - truth["v"][j]) <= max(w, h)
                ):
                    steady_taken += 1
                drawn.append(colour_drawn(colours[i], cu, cv_, sea))
                s_sea, su, sv = saliency(image, pose, i, session, cu, cv_, sea)
                if s_sea is not None and math.hypot(su - u, sv - v) > max(w, h):
                    distinct.append(s_sea)
        rows.append(
            {
                "frame": i,
                "vehicle": word,
                "vehicle_saliency": s,
                "seafloor_taken": taken,
                "vehicle_steady": steady,
                "seafloor_taken_steady": steady_taken,
                "seafloor_distinct": sorted(distinct),
                "vehicle_colour": colour_drawn(colours[i], u, v, box),
                "seafloor_colours": drawn,
            }
        )
    return {"session": path.name, "rows": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/h1-waves"))
    parser.add_argument("--out", type=Path)
    parser.add_argument("--follow", action="store_true", help="also boxes followed for a second")
    parser.add_argument(
        "--luma", action="store_true", help="the frames' luma planes (as live) instead of BGR"
    )
    parser.add_argument("--only", nargs="*", help="only these sessions (names)")
    args = parser.parse_args()
    sessions = sorted(p for p in args.work.glob("w*") if (p / "session.toml").exists())
    sessions += sorted((ROOT / "sim_fixtures" / "bundled").glob("*/"))
    if args.only:
        sessions = [p for p in sessions if p.name in args.only]
    results = [run(p, args.luma) for p in sessions if (p / "track.csv").exists()]
    p = DetectParams()
    head = (
        f"The live box check on one frame (min_saliency {p.min_saliency:g}, distinct {p.distinct:g}) and over "
        f"{STEADY_S:g} s of frames (steady) on the UUV and the seafloor, frames {FRAMES}, "
        f"{'luma' if args.luma else 'BGR'}"
    )
    columns = (
        "session                frame  vehicle  saliency  seafloor boxes taken  steady: vehicle  seafloor taken"
        "  seafloor distinct (largest 3)"
    )
    lines = [head, columns]
    for r in results:
        for row in r["rows"]:
            s = row["vehicle_saliency"]
            top = ", ".join(f"{x:.1f}" for x in row["seafloor_distinct"][-3:])
            lines.append(
                f"{r['session']:22s} {row['frame']:5d}  {row['vehicle']:8s} "
                f"{'-' if s is None else f'{s:.1f}':>8s}  {row['seafloor_taken']:20d}  "
                f"        {row['vehicle_steady']:8s}  {row['seafloor_taken_steady']:14d}  {top}"
            )
    for name, key in (("one frame", "seafloor_taken"), ("steady", "seafloor_taken_steady")):
        rows = [row for r in results for row in r["rows"]]
        kept = sum(
            row["vehicle" if key == "seafloor_taken" else "vehicle_steady"] != "refused"
            for row in rows
        )
        lines.append(
            f"{name}: UUV boxes taken {kept} of {len(rows)}, seafloor boxes taken {sum(row[key] for row in rows)}"
        )
    rows = [row for r in results for row in r["rows"]]
    uuv = np.array([row["vehicle_colour"] for row in rows])
    sea = np.array([c for row in rows for c in row["seafloor_colours"]])
    lines.append(
        f"colour when drawn (ring spreads): UUV boxes {np.nanmin(uuv):.2f}-{np.nanmax(uuv):.2f}, "
        f"{np.sum(uuv >= STEADY_COLOUR_MIN)} of {len(uuv)} at least STEADY_COLOUR_MIN {STEADY_COLOUR_MIN:g}; "
        f"seafloor boxes at most {np.nanmax(sea):.2f}, {np.sum(sea >= STEADY_COLOUR_MIN)} of {len(sea)} at least it"
    )
    follows = []
    if args.follow:
        lines += [
            "",
            f"Boxes taken unchecked, followed {FOLLOW} frames: ok, distinct's median, share >= {SURE_DISTINCT:g}",
            "session         frame  UUV's box               seafloor boxes: n, largest ok, median, share",
        ]
        for p in sessions:
            if not p.name.startswith("w"):
                continue
            for start in (0, 60):
                f = followed(p, start)
                follows.append(f)
                uuv, sea = f["uuv"], f["seafloor"]
                lines.append(
                    f"{f['session']:15s} {start:5d}  ok {uuv['ok']:2d} {uuv['distinct_median']:5.2f} "
                    f"{uuv['sure_share']:4.2f}       {len(sea):2d}, "
                    f"{max(r['ok'] for r in sea)}, {np.nanmax([r['distinct_median'] for r in sea]):.2f}, "
                    f"{max(r['sure_share'] for r in sea):.2f}"
                )
    lines.append(f"load average (1 min) {os.getloadavg()[0]:.1f}")
    emit(lines, args.out, {"boxes": results, "followed": follows})


if __name__ == "__main__":
    main()
