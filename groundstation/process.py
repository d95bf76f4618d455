"""``skyfix process``: a recorded session in, ``positions.csv`` out.

Pixels come from ``track.csv`` (``--use-track``, geometry only) or from tracking
the session's video. ``--no-refraction`` runs the paper's straight-ray method.
"""

from __future__ import annotations

import sys
from collections import Counter

import numpy as np

from localizer.fix import Fixes, locate
from localizer.height import take_notices
from localizer.pose import camera_pose
from localizer.tracking import TRACKERS

from .outputs import output_dir
from .positions import write_positions_csv
from .session import Session, SessionError, load_session

# Per-frame statuses that, when no frame at all has a fix, mean the session itself is wrong.
_GEOMETRY_FAILURES = ("no_water", "below_surface", "bad_pixel")


def frame_pixels(session: Session, use_track: bool, tracker: str = "default", progress: bool = False):
    """``(t, u, v, track_status)`` per frame: from track.csv or from tracking the video."""
    if use_track:
        if session.track is None:
            raise SessionError(f"{session.path / 'track.csv'}: missing (needed by --use-track)")
        tr = session.track
        status = np.full(len(tr["t"]), "ok", dtype=object)
        return tr["t"], tr["u"], tr["v"], status
    if session.video_path is None:
        raise SessionError(f"{session.path}: no video.* file (use --use-track to take pixels from track.csv)")
    from .track_video import track_session

    tracked = track_session(session, tracker_name=tracker, progress=progress)
    session.warnings.extend(tracked.warnings)
    return tracked.t, tracked.u, tracked.v, tracked.status


def locate_frames(session: Session, pixels, refraction: bool = True) -> Fixes:
    """Fixes for ``pixels = (t, u, v, track_status)`` (see :func:`frame_pixels`)."""
    t, u, v, track_status = pixels
    pose = camera_pose(session.calibration, session.telemetry, t)
    session.warnings.extend(f"{session.path}: {notice}" for notice in take_notices(session.telemetry))
    fixes = locate(session.calibration, pose, u, v, refraction=refraction)
    lost = (track_status != "ok") & (pose.status == "ok")
    fixes.status[lost] = track_status[lost]
    if len(fixes) and not np.any(fixes.status == "ok"):
        geo = np.flatnonzero(np.isin(fixes.status, _GEOMETRY_FAILURES))
        if len(geo):
            i = geo[0]
            raise SessionError(
                f"{session.path}: no frame has a fix; first frame (t = {t[i]:.3f}, u = {u[i]:.1f}, v = {v[i]:.1f}) "
                f"is {fixes.status[i]} (camera height {pose.height_m[i]:.2f} m): check [mount] and [water]"
            )
    return fixes


def process_session(
    session: Session, use_track: bool, refraction: bool = True, tracker: str = "default", progress: bool = False
) -> Fixes:
    """Fixes for every frame of a session (pixels from track.csv or the tracker)."""
    return locate_frames(session, frame_pixels(session, use_track, tracker, progress), refraction)


def summary(fixes: Fixes) -> str:
    counts = Counter(fixes.status)
    parts = ", ".join(f"{k} {n}" for k, n in counts.most_common())
    return f"{len(fixes)} frames: {parts}"


def print_warnings(session: Session) -> None:
    """The session's warnings not printed yet (reading, tracking, height sources), one line each on stderr."""
    for w in session.warnings:
        print(f"warning: {w}", file=sys.stderr)
    session.warnings.clear()


def run(args) -> int:
    out = output_dir(args.out)
    session = load_session(args.session)
    try:
        fixes = process_session(
            session, use_track=args.use_track, refraction=not args.no_refraction,
            tracker=args.tracker, progress=not args.quiet,
        )
    finally:
        print_warnings(session)
    write_positions_csv(out / "positions.csv", fixes)
    print(f"{summary(fixes)} -> {out / 'positions.csv'}")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("process", help="process a recorded session into positions.csv")
    p.add_argument("session", help="session directory (format v1)")
    p.add_argument("--out", required=True, help="output directory for positions.csv")
    p.add_argument("--use-track", action="store_true", help="take the UUV pixels from track.csv (no tracker)")
    p.add_argument("--no-refraction", action="store_true", help="the paper's straight ray (no Snell refraction)")
    p.add_argument("--tracker", default="default", choices=TRACKERS,
                   help="tracker backend; default: telemetry-guided template matching; mil: the paper's")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
