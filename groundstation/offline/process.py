"""``skyfix process``: a recorded session in, ``positions.csv`` out (each frame's fix as live, causal), and beside it
``positions_smoothed.csv`` (the fixes smoothed over the whole recording: :mod:`groundstation.offline.smoothed`).

A session with several UUVs (``uuvs/<id>/``) is processed as one UUV's (``--uuv``): its depth, its first box
and its ``track.csv``; the UAV's telemetry and the video are shared. ``--uuv all`` processes every UUV of the
session into ``<out>/<id>/`` (the same files, the same results as each alone), tracking them all in one pass
over the video (:func:`tracked_pixels`): each frame decoded once, its UAV pose and the video's motion computed
once.

Pixels come from ``track.csv`` (``--use-track``, geometry only) or from tracking
the session's video. ``--no-refraction`` runs the paper's straight-ray method. The video is tracked once forward
and backward (:func:`groundstation.offline.track.track_session` ``both_ways``): positions.csv has the causal pass's
fixes only (what a live run would have sent); the smoothed track also takes the fixes of the frames traced back from
a re-acquisition (its ``traced_back`` column).

Time: when the UAV link's delay is neither stated (``[timing] mavlink_latency_s``)
nor measured (TIMESYNC in the tlog), the frames' offset to the telemetry is
estimated from the video's motion while it is tracked
(:mod:`groundstation.latency.estimate`) from the whole video and applied as that delay
(time source ``motion``) with a 1-sigma that covers what the video's thirds disagree on
(:attr:`~groundstation.latency.estimate.SessionOffset.sigma_s`), when settled or when that
1-sigma is below the unknown delay's; one line on stderr says what was found. Otherwise (no
such estimate, ``--use-track``, ``--no-motion-offset``) the delay stays unknown: taken as
0, its 1-sigma ``[timing] unknown_latency_sigma_s`` in each fix's h_acc, and a warning says so.

Tracking the video also measures the camera's height from the UUV's size
(``--height-from-size``, :mod:`groundstation.height_from_size`; one estimate for all the UUVs of ``--uuv all``) and
prints its estimate.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import multiprocessing
import sys
from collections import Counter
from typing import NamedTuple

import numpy as np

from groundstation.height_from_size import MODES as SIZE_MODES
from groundstation.height_from_size import HeightFromSize, shared_sizes
from groundstation.latency.estimate import offset_from_rotations
from groundstation.offline.bottom import MODES as BOTTOM_MODES
from groundstation.offline.bottom import NAME as BOTTOM_NAME
from groundstation.offline.bottom import (
    PoseCorrection,
    append_columns,
    locate_on_track,
    pixels_at,
    pose_cells,
    pose_from_bottom,
    write_summary,
)
from groundstation.offline.reference import MODES as REFERENCE_MODES
from groundstation.offline.reference import apply as apply_reference
from groundstation.offline.smoothed import NAME as SMOOTHED_NAME
from groundstation.offline.smoothed import offline_track, traced_back, write_smoothed_csv
from groundstation.offline.smoothed import summary as smoothed_summary
from groundstation.offline.uuv_workers import available, picklable
from groundstation.outputs import output_dir
from groundstation.session.positions import write_positions_csv
from groundstation.session.read import (
    PRIMARY_UUV,
    Session,
    SessionError,
    load_session,
    load_sessions,
    uuv_ids,
    video_file,
)
from groundstation.video.file import decoding_early
from localizer.fix import Fixes, locate
from localizer.fix_gate import MAX_ACCEL_MPS2, MAX_SPEED_MPS
from localizer.height import take_notices
from localizer.pose import camera_pose
from localizer.tracking import GREY_TRACKERS, TRACKERS

#: ``--uuv`` for every UUV of the session (one pass over the video, an output folder each).
ALL_UUVS = "all"
# Per-frame statuses that, when no frame at all has a fix, mean the session itself is wrong.
_GEOMETRY_FAILURES = ("no_water", "below_surface", "bad_pixel")


class Pixels(NamedTuple):
    """The UUV's pixel per frame: times, pixels, the tracker's status words and its 1-sigma of each of u and v
    (None: the calibration's ``[uncertainty] pixel_px``, as for pixels from track.csv)."""

    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    status: np.ndarray
    sigma_px: np.ndarray | None = None
    #: the same frames tracked forward and backward (:func:`frame_pixels` ``both_ways``): these pixels and those of
    #: the frames traced back from a re-acquisition (ok too); None when none was (these are the offline ones too)
    offline: Pixels | None = None


def frame_pixels(
    session: Session,
    use_track: bool,
    tracker: str = "default",
    progress: bool = False,
    motion: bool = True,
    size: HeightFromSize | None = None,
    both_ways: bool = False,
    size_process: bool = False,
) -> Pixels:
    """The UUV's :class:`Pixels` per frame: from track.csv or from tracking the video (causal, as live; with
    ``both_ways`` tracked once forward and backward, :func:`groundstation.offline.track.track_session`, the frames
    traced back in ``offline``).

    Tracking the video of a session whose link delay is unknown, with ``motion``, also estimates the frames'
    offset to the telemetry and applies it when settled (see the module doc); an unknown delay is a warning.
    ``size``: measuring the camera's height from the UUV's size in the same pass; its warnings join the session's
    (``size_process``: measured in a process beside it, :func:`tracked_pixels`).
    """
    if use_track:
        if session.track is None:
            raise SessionError(f"{session.path / 'track.csv'}: missing (needed by --use-track)")
        tr = session.track
        status = np.full(len(tr["t"]), "ok", dtype=object)
        _warn_unknown_delay(session, "pixels from track.csv: no video to estimate it from")
        return Pixels(tr["t"], tr["u"], tr["v"], status)
    if session.video_path is None:
        raise SessionError(
            f"{session.path}: no video.* file (use --use-track to take pixels from track.csv)"
        )
    return tracked_pixels(
        [session], tracker, progress, motion, [size], both_ways, size_process=size_process
    )[0]


def tracked_pixels(
    sessions: list[Session],
    tracker: str = "default",
    progress: bool = False,
    motion: bool = True,
    sizes: list[HeightFromSize | None] | None = None,
    both_ways: bool = False,
    workers: bool = False,
    size_process: bool = False,
) -> list[Pixels]:
    """:func:`frame_pixels` from the video of several UUVs of one session (``sessions``: the session read as each
    UUV's; ``sizes``: one each or None) tracked in one pass
    (:func:`groundstation.offline.track.track_sessions`): the frames' offset to the telemetry is estimated once,
    from the pass's rotations, and applied to each. One :class:`Pixels` per session, each the same as
    :func:`frame_pixels` of that session alone. ``workers``: each UUV tracked in a process of its own;
    ``size_process``: the heights from size measured in a process beside the pass
    (:func:`~groundstation.offline.track.track_sessions`)."""
    from groundstation.offline.track import track_sessions

    first = sessions[0]
    measure = motion and first.telemetry.latency_source == "unknown"
    videos = track_sessions(
        sessions,
        tracker_name=tracker,
        progress=progress,
        measure_motion=measure,
        sizes=sizes,
        both_ways=both_ways,
        workers=workers,
        size_process=size_process,
    )
    found = (
        offset_from_rotations(first.calibration, first.telemetry, videos[0].rotations)
        if measure
        else None
    )
    pixels = []
    for session, tracked, size in zip(sessions, videos, sizes or [None] * len(sessions)):
        session.warnings.extend(tracked.warnings)
        if size is not None:
            session.warnings.extend(size.warnings)
        if found is not None:
            _align_by_motion(session, found, quiet=session is not first)
        _warn_unknown_delay(
            session,
            "--no-motion-offset" if not motion else "no estimate from the video surer than that",
        )
        pixels.append(_pixels_of(tracked))
    return pixels


def _pixels_of(tracked) -> Pixels:
    """A :class:`~groundstation.offline.track.TrackedVideo`'s causal pixels, the frames traced back in
    ``offline``, whose pixels are the ones before the motion filter through waves
    (:class:`~localizer.tracking.motion_filter.MotionFilter`): the smoothed track filters them itself, both ways,
    and measures their noise as a frame's own, which a causal filter's averaging would hide."""
    u, v = (
        (tracked.u, tracked.v)
        if tracked.u_unfiltered is None
        else (tracked.u_unfiltered, tracked.v_unfiltered)
    )
    both = Pixels(tracked.t, u, v, tracked.status, tracked.sigma_px)
    bridged = tracked.bridged is not None and tracked.bridged.any()
    if not bridged and _same(u, tracked.u).all() and _same(v, tracked.v).all():
        return both
    causal = [
        np.where(tracked.bridged, np.nan, a) if bridged else a
        for a in (tracked.u, tracked.v, tracked.sigma_px)
    ]
    status = tracked.causal_status if bridged else tracked.status
    return Pixels(tracked.t, causal[0], causal[1], status, causal[2], both)


def _same(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per frame: the same pixel coordinate (both NaN: no pixel in either)."""
    return (a == b) | (np.isnan(a) & np.isnan(b))


def _align_by_motion(session: Session, found, quiet: bool = False) -> None:
    """Apply the frames' offset to the telemetry ``found`` from the measured rotations of the whole video
    (:func:`~groundstation.latency.estimate.offset_from_rotations`), with its σ covering what the video's thirds
    disagree on, when settled or surer than the unknown delay's σ; ``quiet``: without the line on stderr."""
    applied = found.better_than(session.telemetry.timing.unknown_latency_sigma_s)
    if applied:
        session.telemetry.set_motion_latency(found.estimate.offset_s, found.sigma_s)
    if quiet:
        return
    print(
        f"{session.path.name}: the frames' offset to the telemetry from the video's motion: {found.describe()}"
        + (
            f"; applied as the UAV link's delay: {session.telemetry.uav_latency_s * 1000:.1f} ms "
            f"± {found.sigma_s * 1000:.1f} ms"
            if applied
            else ""
        ),
        file=sys.stderr,
    )


def _warn_unknown_delay(session: Session, why: str) -> None:
    if session.telemetry.latency_source == "unknown":
        session.warnings.append(
            f"{session.path}: the UAV link's delay is unknown (no [timing] mavlink_latency_s, no TIMESYNC in the tlog, "
            f"{why}): taken as 0; h_acc includes ±{session.telemetry.latency_sigma_s * 1000:.0f} ms of it "
            "([timing] unknown_latency_sigma_s) × the camera's motion"
        )


def locate_frames(
    session: Session, pixels, refraction: bool = True, correction: PoseCorrection | None = None
) -> Fixes:
    """Fixes for :class:`Pixels` (or a tuple of its first four, e.g. track.csv's; see :func:`frame_pixels`), the
    poses corrected by ``correction`` (:func:`bottom_correction`) when given."""
    t, u, v, track_status, sigma_px = Pixels(*pixels)[:5]
    pose = camera_pose(session.calibration, session.telemetry, t)
    session.warnings.extend(
        f"{session.path}: {notice}" for notice in take_notices(session.telemetry)
    )
    cal, reported = session.calibration, pose
    if correction is None:
        fixes = locate(cal, pose, u, v, refraction=refraction, sigma_px=sigma_px)
    else:
        pose, cal = correction.apply(session, pose)
        fixes = locate_on_track(cal, pose, u, v, refraction=refraction, sigma_px=sigma_px)
        for name, values in correction.values(session, reported).items():
            setattr(fixes, name, values)
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


def located(
    session: Session,
    pixels: Pixels,
    refraction: bool,
    correction: PoseCorrection | None,
    reference: str,
) -> tuple[Fixes, Fixes, dict | None]:
    """positions.csv's fixes (causal, as live), the smoothed track's (these and the frames traced back,
    ``pixels.offline``) and positions.csv's reference cells (:func:`groundstation.offline.reference.apply`
    ``reference``, the same correction for both; None without one)."""
    if pixels.offline is None:
        fixes, cells = apply_reference(
            session, locate_frames(session, pixels, refraction, correction), reference, correction
        )
        return fixes, fixes, cells
    both = locate_frames(session, pixels.offline, refraction, correction)
    own = locate_frames(session, pixels, refraction, correction)
    if not (_same(pixels.u, pixels.offline.u) | (pixels.status != "ok")).all():
        # a pixel of its own where the offline one is before the motion filter: each set corrected on its own
        causal, cells = apply_reference(session, own, reference, correction)
        return causal, apply_reference(session, both, reference, correction)[0], cells
    both, cells = apply_reference(session, both, reference, correction)
    back = (pixels.offline.status == "ok") & (pixels.status != "ok")
    causal = rows_replaced(both, own, back)
    for column in (cells or {}).values():  # the reference corrects ok fixes only
        for i in np.flatnonzero(back):
            column[i] = ""
    return causal, both, cells


def rows_replaced(fixes: Fixes, other: Fixes, rows: np.ndarray) -> Fixes:
    """``fixes`` with the rows ``rows`` (bool per frame) taken from ``other`` (the same frames)."""
    columns = {}
    for f in dataclasses.fields(fixes):
        mine = getattr(fixes, f.name)
        if isinstance(mine, np.ndarray):
            mine = mine.copy()
            mine[rows] = getattr(other, f.name)[rows]
        columns[f.name] = mine
    return Fixes(**columns)


def process_session(
    session: Session,
    use_track: bool,
    refraction: bool = True,
    tracker: str = "default",
    progress: bool = False,
    motion: bool = True,
    size: HeightFromSize | None = None,
) -> Fixes:
    """Fixes for every frame of a session (pixels from track.csv or the tracker)."""
    return locate_frames(
        session, frame_pixels(session, use_track, tracker, progress, motion, size), refraction
    )


def bottom_correction(
    session: Session, pixels, mode: str, progress: bool = False
) -> PoseCorrection | None:
    """``--pose-from-bottom``: the pose correction from the static seafloor (:mod:`groundstation.offline.bottom`),
    or None (``off``, or nothing to estimate from: a warning says why); one line on stderr says what was found."""
    if mode == "off":
        return None
    t, u, v = Pixels(*pixels)[:3]
    frames_t = session.frames["t"] if session.frames is not None else t
    pose = camera_pose(session.calibration, session.telemetry, frames_t)
    found = pose_from_bottom(session, pose, *pixels_at(frames_t, t, u, v), progress)
    if isinstance(found, str):
        session.warnings.append(f"{session.path}: no pose from the bottom: {found}")
        return None
    print(f"{session.path.name}: {found.describe()}", file=sys.stderr)
    return found


def size_of(session: Session, mode: str, use_track: bool) -> HeightFromSize | None:
    """The height-from-size measurement ``--height-from-size`` asks for, when the video is tracked."""
    if mode == "off" or use_track or session.video_path is None:
        return None
    return HeightFromSize(session.calibration, session.telemetry, mode)


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
    with _decoding_early(args):
        return _run(args)


def _decoding_early(args):
    """The session's video decoding from now on, while the session is read and its poses computed, on a core that
    would be idle meanwhile (:func:`groundstation.video.file.decoding_early`; its tracking takes it): where it is
    tracked here and nothing is forked beside the decoder's threads (not with ``--use-track``, ``--track-workers``,
    ``--beside``)."""
    video = video_file(args.session)
    if video is None or args.use_track or args.track_workers or args.beside:
        return contextlib.nullcontext()
    return decoding_early(video, grey=args.tracker in GREY_TRACKERS)


def _run(args) -> int:
    out = output_dir(args.out)
    if args.uuv != ALL_UUVS:
        return process_one(load_session(args.session, args.uuv), args, out)
    sessions = load_sessions(args.session, uuv_ids(args.session))
    if args.use_track:
        for session in sessions:
            process_one(session, args, output_dir(out / session.uuv_id))
        return 0
    # one estimate of the camera's height for all (not in track workers: each would see its own UUV's alone)
    sizes = (
        [size_of(s, args.height_from_size, args.use_track) for s in sessions]
        if args.track_workers or args.height_from_size == "off" or sessions[0].video_path is None
        else shared_sizes(sessions, args.height_from_size)
    )
    try:
        pixels = tracked_pixels(
            sessions,
            args.tracker,
            not args.quiet,
            not args.no_motion_offset,
            sizes,
            both_ways=True,
            workers=args.track_workers,
            size_process=args.beside,
        )
    finally:
        for session in sessions:
            print_warnings(session)
    jobs = [
        (session, args, output_dir(out / session.uuv_id), (uuv_pixels, size))
        for session, uuv_pixels, size in zip(sessions, pixels, sizes)
    ]
    if args.beside:
        each_beside(process_one, jobs)
    else:
        for job in jobs:
            process_one(*job)
    return 0


def each_beside(work, jobs: list[tuple]) -> None:
    """``work(*job)`` for every job: the first here and the others meanwhile in processes forked for them, where
    the platform forks (``skyfix process --uuv all``: each UUV's geometry and files once the video's pass is done,
    on cores idle by then; issue 30). What the others print is held back and printed after the first's, in order;
    the first error raised is raised here once the jobs before it have printed theirs. Without ``fork``: one after
    the other here."""
    if len(jobs) < 2 or not available():
        for job in jobs:
            work(*job)
        return
    ctx = multiprocessing.get_context("fork")
    others = []
    for job in jobs[1:]:
        mine, theirs = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_beside, args=(work, job, theirs), daemon=True)
        proc.start()
        theirs.close()
        others.append((mine, proc))
    try:
        work(*jobs[0])
        for link, proc in others:
            try:
                out, err, error = link.recv()
            except EOFError:
                raise SessionError(f"{proc.name}: ended (exit code {proc.exitcode})") from None
            sys.stdout.write(out)
            sys.stderr.write(err)
            if error is not None:
                raise error
    finally:
        for link, proc in others:
            if proc.is_alive():
                proc.terminate()
            proc.join()
            link.close()


def _beside(work, job: tuple, link) -> None:
    """:func:`each_beside`'s forked process: ``work(*job)``, what it printed and its error (or None) sent back."""
    out, err = io.StringIO(), io.StringIO()
    error = None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            work(*job)
        except Exception as e:  # noqa: BLE001 - raised again in the main process
            error = picklable(e)
    link.send((out.getvalue(), err.getvalue(), error))


def process_one(session: Session, args, out, tracked: tuple | None = None) -> int:
    """One UUV's ``skyfix process`` into the folder ``out``; ``tracked``: its (:class:`Pixels`, size
    measurement) from a pass over the video shared with the session's other UUVs (:func:`tracked_pixels`)."""
    try:
        if tracked is None:
            size = size_of(session, args.height_from_size, args.use_track)
            pixels = frame_pixels(
                session,
                args.use_track,
                args.tracker,
                not args.quiet,
                not args.no_motion_offset,
                size,
                both_ways=True,
                size_process=args.beside,
            )
        else:
            pixels, size = tracked
        correction = bottom_correction(session, pixels, args.pose_from_bottom, not args.quiet)
        fixes, offline, reference_cells = located(
            session, pixels, not args.no_refraction, correction, args.reference
        )
    finally:
        print_warnings(session)
    write_positions_csv(out / "positions.csv", fixes)
    if correction is not None:
        append_columns(out / "positions.csv", pose_cells(fixes))
        write_summary(out / BOTTOM_NAME, correction)
    if reference_cells is not None:
        append_columns(out / "positions.csv", reference_cells)
    print(f"{summary(fixes)} -> {out / 'positions.csv'}")
    smoothed, status = offline_track(offline, args.uuv_max_speed_mps, args.uuv_max_accel_mps2)
    traced = traced_back(fixes, offline)
    write_smoothed_csv(out / SMOOTHED_NAME, offline, smoothed, status, traced)
    print(f"{smoothed_summary(status, smoothed, traced)} -> {out / SMOOTHED_NAME}")
    if size is not None:
        print(size.summary())
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help)
    p.add_argument("session", help="session directory (format v1)")
    p.add_argument(
        "--out", required=True, help="output directory for positions.csv and positions_smoothed.csv"
    )
    add_uuv_argument(
        p,
        "the UUV to locate: its depth, first box and track (default: %(default)s, the session's own); "
        f"{ALL_UUVS}: every UUV of the session, tracked in one pass over the video, each into --out/<its id>/",
    )
    add_uuv_bounds(p)
    p.add_argument(
        "--use-track", action="store_true", help="take the UUV pixels from track.csv (no tracker)"
    )
    p.add_argument(
        "--no-refraction",
        action="store_true",
        help="the paper's straight ray (no Snell refraction)",
    )
    p.add_argument(
        "--tracker",
        default="default",
        choices=TRACKERS,
        help="tracker backend; default: telemetry-guided template matching; mil: the paper's",
    )
    add_size_argument(p)
    p.add_argument(
        "--pose-from-bottom",
        choices=BOTTOM_MODES,
        default="off",
        help="auto: estimate the drone's attitude biases and GNSS walk from the static seafloor in the "
        "video and correct every frame's pose by what the bottom told (positions.csv says it); "
        "off (default)",
    )
    p.add_argument(
        "--reference",
        choices=REFERENCE_MODES,
        default="auto",
        help="auto (default): where the session has a reference.toml (a surveyed marker of known position, or a "
        "buoy or boat reporting its GNSS from the system_id it names), find the reference in the video and correct "
        "every fix by the drone's absolute offset it shows (positions.csv says it); off",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--track-workers",
        action="store_true",
        help=f"with --uuv {ALL_UUVS}: each UUV tracked in a process of its own, the decoded frames shared (the "
        "same results; it costs CPU, so it only helps with idle cores; where the platform forks)",
    )
    p.add_argument(
        "--beside",
        action="store_true",
        help="the height from the UUV's size measured in a process of its own during the pass over the video, "
        f"and with --uuv {ALL_UUVS} the UUVs' positions and files in processes of their own after it (the same "
        "files; it costs CPU, so it only helps with idle cores; where the platform forks)",
    )
    add_motion_offset_flag(p)
    p.set_defaults(func=run)


def add_uuv_argument(p, text: str, default: str | None = PRIMARY_UUV) -> None:
    p.add_argument("--uuv", default=default, metavar="ID", help=text)


def add_uuv_bounds(p) -> None:
    """The UUV's top speed and acceleration: the bounds of the smoothed track's model (as the live gates')."""
    p.add_argument(
        "--uuv-max-speed-mps",
        metavar="MPS",
        type=float,
        default=MAX_SPEED_MPS["bluerov2"],
        help="the UUV's top speed, for the smoothed track (default: a BlueROV2's, %(default)g)",
    )
    p.add_argument(
        "--uuv-max-accel-mps2",
        metavar="MPS2",
        type=float,
        default=MAX_ACCEL_MPS2["bluerov2"],
        help="the UUV's largest acceleration, for the smoothed track (default %(default)g)",
    )


def add_motion_offset_flag(p) -> None:
    p.add_argument(
        "--no-motion-offset",
        action="store_true",
        help="do not estimate the frames' offset to the telemetry from the video's motion where the UAV "
        "link's delay is neither stated nor measured (it stays unknown: 0, with its sigma in h_acc)",
    )


def add_size_argument(p) -> None:
    p.add_argument(
        "--height-from-size",
        choices=SIZE_MODES,
        default="check",
        help="the camera's height from the UUV's size in the tracked video: check (default: estimate it, "
        "warn when the configured height disagrees), auto (also hand it to the height's fusion once sure), "
        "off",
    )
