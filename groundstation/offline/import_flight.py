"""``skyfix import``: a field day's own records as a session (format v1) that every offline command reads.

    skyfix import --dataflash FLIGHT.bin --video CAMERA.mp4 --depth DEPTH --calibration CAL.toml --out SESSION

- The drone's DataFlash log (:mod:`groundstation.session.dataflash`) becomes the session's
  ``uav.tlog``: the MAVLink messages its records stand for, each at its own record's time —
  ATTITUDE (ATT, with the IMU's body rates), GLOBAL_POSITION_INT (POS), GPS_RAW_INT (GPS,
  GPA), SYSTEM_TIME (the log's clock on UNIX time from the GPS fixes' week and ms),
  the gimbal's attitude (MNT) as the message the calibration names — MOUNT_ORIENTATION
  (``attitude_source = "mount_orientation"``) or GIMBAL_DEVICE_ATTITUDE_STATUS (``"gimbal_device"``, what
  ArduCopter sends live: roll and pitch from the horizon, the yaw relative to the vehicle), so the calibration of
  the live run serves the import of its log —, DISTANCE_SENSOR (RFND), HEARTBEAT (armed as
  the log's ARM / EV records say) and PARAM_VALUE ``MNT1_TYPE``. Nothing is resampled: one
  message per record; times are whole milliseconds of the autopilot's clock (its MAVLink
  ``time_boot_ms``), the record time the same instant on UNIX time (a log has no radio delay).
- The camera's own video has no per-frame station times: its frames are timed by the
  container (PTS) from a start on UNIX time — found from the image's motion against the
  logged attitude (``--video-start motion``, the default: the camera's rotation between
  frames against the attitude's, :func:`~groundstation.latency.estimate.find_video_start`,
  searched across the whole log and refined by the estimator that measures the live video's
  latency, on the whole video (read grey, never held in memory), its thirds refined alone;
  its sigma and residual printed and kept), or ``--video-start trigger``: the first
  CAM/TRIG record of the log (the camera started recording when triggered), or
  ``--video-start-unix``. A video that does not lie within the log's attitude is an error
  naming both spans. The video is linked into the session (a hard link where the file
  system allows, else copied).
- Or a DJI drone's flight record exported as CSV (``--dji-csv``, :mod:`groundstation.session.dji`):
  the same messages from its OSD and GIMBAL columns; and the camera's ``.SRT`` (``--srt``) gives
  the video's start: its frames' camera-clock times, that clock's zone found by matching the
  SRT's per-frame track against the record's (or ``--srt-utc-offset-h``); the older ``GPS(...)``
  form's latitude/longitude order found the same way (or ``--srt-gps-order``).
- The depth: skyfix's ``depth.jsonl`` (read strictly), ArduSub's own DataFlash log (``.bin``: its depth sensor's
  depth as ArduSub logged it, on UNIX time from the GPS_INPUT it received:
  :mod:`groundstation.session.ardusub_log`), or a CSV with a header naming ``t`` (UNIX s) and ``depth_m``
  (metres below the surface) columns, as ``--depth-columns`` says.
- ``session.toml``: the calibration's text, with ``version = 1`` first when it lacks it.
- ``import.json``: what the import found: the log's clock to UNIX offset and its sigma, the
  video's start and where it came from, the records used per kind, and the warnings.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import sys
import tomllib
from pathlib import Path

import numpy as np

from groundstation.config_files import load_calibration
from groundstation.latency.estimate import VideoStart, find_video_start, measure_rotations
from groundstation.mavlink.ingest import mavutil
from groundstation.offline.progress import progress as progress_bar
from groundstation.outputs import output_dir
from groundstation.session import SessionError
from groundstation.session.ardusub_log import read_ardusub_depth
from groundstation.session.dataflash import DOWNWARD, FlightLog, read_dataflash
from groundstation.session.depth import read_depth
from groundstation.session.dji import read_dji_csv, read_srt, srt_clock, srt_video_start
from groundstation.session.read import load_session
from groundstation.session.tlog import tlog_record
from groundstation.video.file import frame_times
from groundstation.video.frames import VideoError
from localizer.attitude import GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME, euler_to_quat

HEARTBEAT_HZ = 1.0


def telemetry_messages(flight: FlightLog, gimbal: str) -> list[tuple[float, object]]:
    """``(boot s, message)`` for every record (see the module doc), in time order; the MNT records as the
    ``gimbal`` message (``[mount] attitude_source``: none for "fixed")."""
    mav = mavutil().mavlink
    out: list[tuple[float, object]] = []

    def ms(t: float) -> int:
        return round(t * 1000.0)

    for t, roll, pitch, yaw, p, q, r in flight.att:
        out.append((t, mav.MAVLink_attitude_message(ms(t), roll, pitch, yaw, p, q, r)))
    yaw_at = (
        np.degrees(np.interp(flight.pos[:, 0], flight.att[:, 0], np.unwrap(flight.att[:, 3])))
        % 360.0
    )
    for (t, lat, lon, alt, rel), hdg in zip(flight.pos, yaw_at, strict=True):
        out.append(
            (
                t,
                mav.MAVLink_global_position_int_message(
                    ms(t),
                    round(lat * 1e7),
                    round(lon * 1e7),
                    round(alt * 1000),
                    round(rel * 1000),
                    0,
                    0,
                    0,
                    round(hdg * 100) % 36000,
                ),
            )
        )
    for t, unix, status, sats, hdop, alt, h_acc, v_acc, lat, lon in flight.gps:
        known = math.isfinite(unix)
        out.append(
            (
                t,
                mav.MAVLink_gps_raw_int_message(
                    round(unix * 1e6) if known else 0,
                    int(status),
                    round(lat * 1e7),
                    round(lon * 1e7),
                    round(alt * 1000),
                    round(hdop * 100) if math.isfinite(hdop) else 65535,
                    65535,
                    65535,
                    65535,
                    int(sats),
                    h_acc=round(h_acc * 1000) if math.isfinite(h_acc) else 0,
                    v_acc=round(v_acc * 1000) if math.isfinite(v_acc) else 0,
                ),
            )
        )
        if known and status >= 3:
            out.append(
                (t, mav.MAVLink_system_time_message(round(float(flight.unix(t)) * 1e6), ms(t)))
            )
    if gimbal == "mount_orientation":
        for t, roll, pitch, yaw_body, yaw_earth in flight.mnt:
            out.append(
                (t, mav.MAVLink_mount_orientation_message(ms(t), roll, pitch, yaw_body, yaw_earth))
            )
    elif (
        gimbal == "gimbal_device"
    ):  # the same angles as one rotation, its yaw flagged as the vehicle's
        for t, roll, pitch, yaw_body, _ in flight.mnt:
            q = euler_to_quat(*np.radians((roll, pitch, yaw_body)))
            out.append(
                (
                    t,
                    mav.MAVLink_gimbal_device_attitude_status_message(
                        0,
                        0,
                        ms(t),
                        GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME,
                        [float(x) for x in q],
                        math.nan,
                        math.nan,
                        math.nan,
                        0,
                        math.radians(yaw_body),
                    ),
                )
            )
    for t, dist in flight.rangefinder:
        out.append(
            (
                t,
                mav.MAVLink_distance_sensor_message(
                    ms(t), 0, 0, round(dist * 100), 0, 0, DOWNWARD, 0
                ),
            )
        )
    armed, events = False, list(flight.armed)
    for t in np.arange(flight.att[0, 0], flight.att[-1, 0], 1.0 / HEARTBEAT_HZ):
        while events and events[0][0] <= t:
            armed = events.pop(0)[1]
        base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
            mav.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
        )
        out.append(
            (
                t,
                mav.MAVLink_heartbeat_message(
                    mav.MAV_TYPE_QUADROTOR,
                    mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
                    base,
                    0,
                    mav.MAV_STATE_ACTIVE,
                    3,
                ),
            )
        )
    if "MNT1_TYPE" in flight.params:
        name = b"MNT1_TYPE"
        out.append(
            (
                flight.att[0, 0],
                mav.MAVLink_param_value_message(
                    name, flight.params["MNT1_TYPE"], mav.MAV_PARAM_TYPE_REAL32, 0, 65535
                ),
            )
        )
    out.sort(key=lambda item: item[0])
    return out


def write_tlog(
    path: Path, flight: FlightLog, messages: list[tuple[float, object]]
) -> dict[str, int]:
    """``uav.tlog`` of ``messages``, each at its time on UNIX time; the count per type."""
    mav = mavutil().mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    counts: dict[str, int] = {}
    with open(path, "wb") as f:
        for t, msg in messages:
            f.write(tlog_record(round(float(flight.unix(t)) * 1e6), msg.pack(mav)))
            counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    return counts


def video_start(flight: FlightLog, how: str, start_unix: float | None) -> tuple[float, str]:
    """The video's first frame on UNIX time and where it came from (given or triggered; the motion's is found once
    the telemetry is written: :func:`start_from_motion`)."""
    if start_unix is not None:
        return start_unix, "given (--video-start-unix)"
    if how == "trigger":
        if not len(flight.triggers_s):
            raise SessionError(
                f"{flight.path}: no CAM or TRIG record: the camera's start is not in the log "
                "(give --video-start-unix, or let the image's motion find it)"
            )
        return float(
            flight.unix(flight.triggers_s[0])
        ), f"the log's first CAM/TRIG record ({len(flight.triggers_s)})"
    return flight.span_unix[0], "motion"


def start_from_srt(
    flight: FlightLog, srt: Path, utc_offset_h: float | None, gps_order: str | None = None
) -> tuple[float, str, dict]:
    """The video's first frame on UNIX time from the camera's SRT, where it came from, and what goes into
    ``import.json``."""
    track = read_srt(srt)
    clock = srt_clock(track, flight, utc_offset_h, gps_order)
    start, spread = srt_video_start(track, clock)
    hours = clock.offset_s / 3600.0
    how = (
        f"the SRT's frame times, camera clock UTC{hours:+.4f} h "
        f"({'found from its track against the record' if clock.found else 'given'}: track residual "
        f"{clock.residual_m:.2f} m over {clock.frames} "
        + (
            "frames)"
            if track.form == "frame"
            else f"subtitles; the older GPS(...) form read as {clock.gps_order}, whole-second camera clock)"
        )
    )
    older = (
        {}
        if track.form == "frame"
        else {
            "srt_gps_order": clock.gps_order,
            "srt_gps_order_residuals_m": [
                round(r, 3) if math.isfinite(r) else None for r in clock.order_residuals_m
            ],
        }
    )
    return (
        start,
        how,
        {
            "srt": str(srt),
            "srt_form": track.form,
            "srt_utc_offset_h": round(hours, 6),
            "srt_utc_offset_found": clock.found,
            "srt_track_residual_m": round(clock.residual_m, 3),
            "srt_frames": clock.frames,
            "srt_start_spread_s": round(spread, 6),
        }
        | older,
    )


def start_from_motion(
    session: Path,
    video: Path,
    index: np.ndarray,
    t_rel: np.ndarray,
    span: tuple[float, float],
    progress: bool = False,
) -> VideoStart:
    """The video's start from its motion (the whole video) against the session's (just written)
    telemetry."""
    s = load_session(session)
    times = np.full(int(index.max()) + 1, np.nan)
    times[index] = t_rel
    bar = progress_bar(len(t_rel), f"{video.name}: the image's motion", progress)
    try:
        rotations = measure_rotations(video, s.calibration, times, bar=bar)
    finally:
        bar.close()
    try:
        return find_video_start(s.calibration, s.telemetry, rotations, span)
    except ValueError as e:
        raise SessionError(
            f"{video}: {e} (its {t_rel[-1]:.1f} s against the log's attitude "
            f"{span[0]:.3f}–{span[1]:.3f})"
        ) from None


def depth_records(
    path: Path, columns: tuple[str, str], sigma_m: float, warnings: list[str]
) -> tuple[list[dict], dict]:
    """``depth.jsonl`` records from a depth.jsonl, ArduSub's DataFlash log (``.bin``: its sensor's 1-sigma
    ``sigma_m``) or a CSV with the named columns; and what the reader found."""
    if path.suffix == ".jsonl":
        return [{"t": r.t, "depth_m": r.depth_m} for r in read_depth(path, warnings)], {
            "depth": str(path)
        }
    if path.suffix.lower() == ".bin":
        return read_ardusub_depth(path, sigma_m, warnings)
    t_col, d_col = columns
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            missing = [c for c in columns if c not in (reader.fieldnames or [])]
            if missing:
                raise SessionError(
                    f"{path}: no column {', '.join(missing)} (header {reader.fieldnames}); "
                    "name them with --depth-columns T,DEPTH"
                )
            out = []
            for i, row in enumerate(reader, start=2):
                try:
                    t, d = float(row[t_col]), float(row[d_col])
                except (TypeError, ValueError):
                    raise SessionError(
                        f"{path}:{i}: {t_col} = {row[t_col]!r}, {d_col} = {row[d_col]!r}: "
                        "not numbers"
                    ) from None
                if not (math.isfinite(t) and math.isfinite(d)) or (out and t <= out[-1]["t"]):
                    raise SessionError(
                        f"{path}:{i}: {t_col} = {t!r}, {d_col} = {d!r}: not finite, or the time "
                        "does not increase"
                    )
                out.append({"t": t, "depth_m": d})
    except OSError as e:
        raise SessionError(f"{path}: cannot read: {e.strerror}") from None
    return out, {"depth": str(path), "columns": list(columns)}


def write_frames(session: Path, index: np.ndarray, t_unix: np.ndarray) -> None:
    with open(session / "video_frames.csv", "w") as f:
        f.write("frame,t\n" + "".join(f"{i},{t:.6f}\n" for i, t in zip(index, t_unix, strict=True)))


def link_or_copy(src: Path, dst: Path) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def import_flight(
    dataflash: Path | None,
    video: Path | None,
    depth: Path,
    calibration: Path,
    out: Path,
    video_start_how: str = "motion",
    video_start_unix: float | None = None,
    depth_columns: tuple[str, str] = ("t", "depth_m"),
    progress: bool = False,
    dji_csv: Path | None = None,
    dji_csv_utc_offset_h: float | None = None,
    srt: Path | None = None,
    srt_utc_offset_h: float | None = None,
    srt_gps_order: str | None = None,
) -> dict:
    """Write the session (see the module doc) from a DataFlash log or a DJI flight record (``dji_csv``); returns
    what ``import.json`` holds."""
    if srt is not None and (video is None or video_start_unix is not None):
        raise SessionError(
            "options: --srt needs --video, and gives the video's start (not with --video-start-unix)"
        )
    if srt is None and (srt_utc_offset_h is not None or srt_gps_order is not None):
        raise SessionError(
            "options: --srt-utc-offset-h and --srt-gps-order are the --srt's: give it"
        )
    cal = load_calibration(str(calibration))
    source = cal.mount.attitude_source
    log = dji_csv if dji_csv is not None else dataflash
    flight = (
        read_dji_csv(dji_csv, dji_csv_utc_offset_h)
        if dji_csv is not None
        else read_dataflash(dataflash)
    )
    if source != "fixed" and not len(flight.mnt):
        raise SessionError(
            f"{dataflash}: no MNT records, while the calibration's camera is on a gimbal (log the "
            "camera bit of LOG_BITMASK)"
        )
    warnings = list(flight.warnings)
    depth_out, depth_found = depth_records(depth, depth_columns, cal.sigmas.depth_m, warnings)
    if not depth_out:
        raise SessionError(f"{depth}: no depth records")
    report: dict = {
        "dji_csv" if dji_csv is not None else "dataflash": str(log),
        "unix_minus_boot_s": round(flight.unix_minus_boot_s, 6),
        "unix_minus_boot_sigma_s": round(flight.unix_minus_boot_sigma_s, 6),
        "log_span_unix": [round(x, 3) for x in flight.span_unix],
        "depth": depth_found,
    }
    frames = None
    if video is not None:
        try:
            index, t_rel = frame_times(video)
        except VideoError as e:
            raise SessionError(str(e)) from None
        if srt is not None:
            start, how, srt_report = start_from_srt(flight, srt, srt_utc_offset_h, srt_gps_order)
            report |= srt_report
        else:
            start, how = video_start(flight, video_start_how, video_start_unix)
        span, log_span = (start, start + float(t_rel[-1])), flight.span_unix
        if how != "motion" and (span[0] < log_span[0] or span[1] > log_span[1]):
            raise SessionError(
                f"{video}: its frames span {span[0]:.3f}–{span[1]:.3f} (UNIX s), not within the log's "
                f"attitude {log_span[0]:.3f}–{log_span[1]:.3f}"
            )
        frames = (index, start + t_rel)
        report |= {
            "video": str(video),
            "video_start_unix": round(start, 6),
            "video_start_from": how,
            "frames": len(index),
        }
    out.mkdir(parents=True, exist_ok=True)
    text = Path(calibration).read_text()
    if "version" not in tomllib.loads(text):
        text = "version = 1\n" + text
    (out / "session.toml").write_text(text)
    report["messages"] = write_tlog(out / "uav.tlog", flight, telemetry_messages(flight, source))
    (out / "depth.jsonl").write_text("".join(json.dumps(r) + "\n" for r in depth_out))
    if frames is not None:
        target = out / f"video{video.suffix.lower() or '.mp4'}"
        link_or_copy(video, target)
        write_frames(out, *frames)
        if report["video_start_from"] == "motion":
            found = start_from_motion(
                out, video, frames[0], frames[1] - frames[1][0], flight.span_unix, progress
            )
            write_frames(out, frames[0], found.start_s + frames[1] - frames[1][0])
            report |= {
                "video_start_unix": round(found.start_s, 6),
                "video_start_from": "the image's motion against the logged attitude",
                "video_start_sigma_s": round(found.sigma_s, 6),
                "video_start_pairs": found.pairs,
                "video_start_rms_mrad": round(found.rms_mrad, 4),
                "video_start_contrast": round(found.contrast, 3),
                "video_start_thirds_unix": [
                    None if t is None else round(t, 6) for t in found.thirds_s
                ],
            }
    report["warnings"] = warnings
    (out / "import.json").write_text(json.dumps(report, indent=1) + "\n")
    return report


def run(args) -> int:
    def path(arg):
        return Path(arg) if arg else None

    out = output_dir(args.out)
    report = import_flight(
        path(args.dataflash),
        path(args.video),
        Path(args.depth),
        Path(args.calibration),
        out,
        args.video_start,
        args.video_start_unix,
        tuple(args.depth_columns.split(",")),
        progress=not args.quiet,
        dji_csv=path(args.dji_csv),
        dji_csv_utc_offset_h=args.dji_csv_utc_offset_h,
        srt=path(args.srt),
        srt_utc_offset_h=args.srt_utc_offset_h,
        srt_gps_order=args.srt_gps_order,
    )
    for w in report["warnings"]:
        print(f"skyfix import: warning: {w}", file=sys.stderr)
    print(
        f"skyfix import: {out}: log clock on UNIX time {report['unix_minus_boot_s']:.3f} s "
        f"± {report['unix_minus_boot_sigma_s'] * 1000:.1f} ms; telemetry {report['messages']}"
        + (
            f"; video {report['frames']} frames from {report['video_start_unix']:.3f} "
            f"({report['video_start_from']}"
            + (
                f": ± {report['video_start_sigma_s'] * 1000:.1f} ms, residual {report['video_start_rms_mrad']:.2f} "
                f"mrad over {report['video_start_pairs']} frame pairs"
                if "video_start_sigma_s" in report
                else ""
            )
            + ")"
            if "frames" in report
            else ""
        )
    )
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help)
    log = p.add_mutually_exclusive_group(required=True)
    log.add_argument("--dataflash", help="the drone's ArduPilot DataFlash log (.bin)")
    log.add_argument(
        "--dji-csv",
        help="a DJI drone's flight record as CSV (dji-log-parser's, PhantomHelp's or Airdata's)",
    )
    p.add_argument(
        "--dji-csv-utc-offset-h",
        type=float,
        help="the zone (hours east of UTC) of a DJI CSV that has local times only (PhantomHelp's)",
    )
    p.add_argument(
        "--srt",
        help="the DJI camera's .SRT beside the video: the frames' times give the video's start",
    )
    p.add_argument(
        "--srt-utc-offset-h",
        type=float,
        help="the SRT's camera clock zone (hours east of UTC); default: found from its track",
    )
    p.add_argument(
        "--srt-gps-order",
        choices=("lat,lon", "lon,lat"),
        metavar="lat,lon|lon,lat",
        help="the older SRT form's GPS(a, b) order; default: found from its track against the record",
    )
    p.add_argument("--video", help="the camera's own video file")
    p.add_argument(
        "--depth",
        required=True,
        help="the UUV's depth: skyfix's depth.jsonl, ArduSub's DataFlash log (.bin) or a CSV",
    )
    p.add_argument(
        "--depth-columns", default="t,depth_m", help="a CSV's time (UNIX s) and depth (m) columns"
    )
    p.add_argument(
        "--calibration", required=True, help="the camera's calibration (TOML, session.toml tables)"
    )
    p.add_argument(
        "--video-start",
        choices=("motion", "trigger"),
        default="motion",
        help="the video's first frame: found from the image's motion against the logged attitude "
        "(default), or the log's first CAM/TRIG record",
    )
    p.add_argument("--video-start-unix", type=float, help="the video's first frame, UNIX s")
    p.add_argument("--out", required=True, help="the session directory to write")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
