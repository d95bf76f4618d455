"""``skyfix replay SESSION``: re-stream a recorded session live, with its original pacing.

Everything is shifted in time by one offset ``shift_s`` (now + a short lead − the
session's first time, or ``--shift-s``), printed first as a JSON line, so that the replayed world
agrees with itself:

- ``uav.tlog``: each MAVLink frame is sent over UDP (``--mavlink-out``, default
  ``udpout:127.0.0.1:14550``) at its record time + shift. The UNIX times in it are
  shifted by the same amount (re-packed with the original system, component and
  sequence): SYSTEM_TIME's ``time_unix_usec``, GPS_RAW_INT's ``time_usec``, and
  the ``ts1`` of TIMESYNC replies (the recording station's clock), so a live
  run measures the recorded link delay and clock offsets again. Every other
  frame goes out byte for byte.
- ``depth.jsonl``: each sample is published over Zenoh on ``--depth-key`` as
  ``{"t": t + shift, "depth_m": ...}`` at its recorded arrival ``t_recv`` + shift
  (``t`` + shift when it has none), so a UUV clock that was off stays off. A session of several UUVs: each
  other UUV's ``uuvs/<id>/depth.jsonl`` on its own key (``--uuv-depth-key ID=KEY``).
- The video: sent in-process as MPEG-TS to ``--video-out`` (default
  ``udp://127.0.0.1:5600``; ``rtp://host:port`` sends RTP; ``zenoh:video/<source>/stream`` publishes it
  as BlueOS's camera manager does, :func:`groundstation.video.zenoh_video.publish_video`), each frame at its
  ``video_frames.csv`` time + shift (+ ``--video-delay-ms``) by the file's
  timestamps (:func:`groundstation.video.send.send_video`): a camera whose
  glass-to-first-packet latency is ``--video-delay-ms`` (default 0).
- A UUV-side endpoint (``--uuv-listen``, default ``udpin:127.0.0.1:14660``)
  writes every GPS_INPUT it receives as one JSON line (``--uuv-log``, default
  stdout), with its receive time (a UDP datagram's as the kernel received it: the replay's own load does not
  stretch the gaps): what the UUV's autopilot would get. Its connection strings are those of skyfix's own links
  (``udpin:``, ``tcpin:``, ``tcp:``, a serial device: :mod:`groundstation.mavlink.transport`). Like the
  autopilot, it sends a HEARTBEAT (system 1, ArduPilot, submarine) a second back to GPS_INPUT's sender.

``--cut INPUT:START_S:DURATION_S`` (repeatable; INPUT ``mavlink``, ``depth`` or ``video``) leaves that
input out from START_S to START_S + DURATION_S seconds after the session's start while the others
keep flowing: a radio link, a depth publisher or a camera link that drops out. The video comes back
at its first keyframe after the cut, as a camera's stream does. When an input comes back the replay
prints ``{"event": "back", "input": ..., "t": <UNIX s of its first message or packet>}``.

Replay ends after the session (plus ``--tail-s``) or ``--duration-s``; its exit code is 1 when a
UUV-side endpoint was listening and no GPS_INPUT came back.
"""

from __future__ import annotations

import argparse
import json
import logging
import select
import sys
import threading
import time
from functools import partial
from pathlib import Path

from groundstation.mavlink.ingest import LinkError, connect, mavutil
from groundstation.mavlink.link import HEARTBEAT_PERIOD_S
from groundstation.mavlink.transport import open_transport
from groundstation.runtime.zenoh_session import open_session, put_json
from groundstation.session.depth import read_depth
from groundstation.session.read import SessionError, read_table, uuv_files
from groundstation.session.tlog import read_tlog
from groundstation.video.send import send_video
from groundstation.video.zenoh_video import publish_video

log = logging.getLogger("skyfix.replay")

CUT_INPUTS = ("mavlink", "depth", "video")
UUV_SYSID = 1  # the UUV endpoint's HEARTBEAT: ArduSub's system id


def parse_uuv_key(text: str) -> tuple[str, str]:
    """``ID=KEY`` → ``(id, key)``; argparse's type for ``--uuv-depth-key``."""
    uuv_id, sep, key = text.partition("=")
    if not (sep and uuv_id and key):
        raise argparse.ArgumentTypeError(f"{text!r}: expected ID=KEY (uuv2=uuv/uuv2/depth)")
    return uuv_id, key


def parse_cut(text: str) -> tuple[str, float, float]:
    """``INPUT:START_S:DURATION_S`` → ``(input, start_s, end_s)``; argparse's type for ``--cut``."""
    parts = text.split(":")
    try:
        name, start_s, duration_s = parts[0], float(parts[1]), float(parts[2])
        if len(parts) != 3 or name not in CUT_INPUTS or not start_s >= 0 or not duration_s > 0:
            raise ValueError
    except (IndexError, ValueError):
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected INPUT:START_S:DURATION_S with INPUT one of "
            f"{', '.join(CUT_INPUTS)}, START_S ≥ 0 and DURATION_S > 0"
        ) from None
    return name, start_s, start_s + duration_s


class Cuts:
    """Which of an input's messages a ``--cut`` leaves out, by session seconds after the start; says when it is back."""

    def __init__(self, cuts, input_: str):
        self.input = input_
        self.windows = sorted((a, b) for name, a, b in cuts or () if name == input_)
        self._in_cut = False

    def skip(self, t_s: float, resumable: bool = True) -> bool:
        """Whether the message at ``t_s`` is left out (``resumable``: it can start the input again)."""
        if any(a <= t_s < b for a, b in self.windows) or (self._in_cut and not resumable):
            self._in_cut = True
            return True
        if self._in_cut:
            self._in_cut = False
            print(json.dumps({"event": "back", "input": self.input, "t": time.time()}), flush=True)
        return False


def depth_to_send(path: Path) -> list[tuple[float, float, float]]:
    """``(t_send, t, depth_m)`` of depth.jsonl's records (read leniently: a bad line is skipped with a warning),
    in sending order; ``t_send`` is the recorded arrival ``t_recv``, or ``t`` without one."""
    warnings: list[str] = []
    out = [
        (r.t if r.t_recv is None else r.t_recv, r.t, r.depth_m)
        for r in read_depth(path, warnings, strict=False)
    ]
    for w in warnings:
        log.warning("%s", w)
    out.sort(key=lambda r: r[0])
    return out


#: UNIX-time fields re-stamped by the replay: message → (field, units per second)
UNIX_FIELDS = {
    "SYSTEM_TIME": ("time_unix_usec", 1e6),
    "GPS_RAW_INT": ("time_usec", 1e6),
    "TIMESYNC": ("ts1", 1e9),
}
_UNIX_MIN_S = 1e9  # a smaller value is a boot time or "unknown" (0), not a UNIX time: left alone


def frame_bytes(msg, shift_s: float) -> bytes:
    """The frame to send: the original bytes, or re-packed with its UNIX time shifted (:data:`UNIX_FIELDS`)."""
    field = UNIX_FIELDS.get(msg.get_type())
    if (
        field is None
        or getattr(msg, field[0]) < _UNIX_MIN_S * field[1]
        or (msg.get_type() == "TIMESYNC" and msg.tc1 == 0)
    ):
        return msg.get_msgbuf()
    name, per_s = field
    mav = mavutil().mavlink.MAVLink(
        None, srcSystem=msg.get_srcSystem(), srcComponent=msg.get_srcComponent()
    )
    mav.seq = msg.get_seq()
    setattr(msg, name, int(getattr(msg, name) + round(shift_s * per_s)))
    return msg.pack(mav)


def _sleep_until(t_unix: float, stop: threading.Event) -> bool:
    """Wait for a UNIX time; False if stopped first."""
    delay = t_unix - time.time()
    return not stop.wait(delay) if delay > 0 else not stop.is_set()


class Replay:
    """The replay's threads and processes; :meth:`run` blocks until the session has been sent."""

    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.dir = Path(args.session)
        if not (self.dir / "session.toml").is_file():
            raise SessionError(f"{self.dir}: not a session directory (no session.toml)")
        self.tlog = read_tlog(self.dir / "uav.tlog")
        if not self.tlog:
            raise SessionError(f"{self.dir / 'uav.tlog'}: no MAVLink frames")
        self.depth = (
            depth_to_send(self.dir / "depth.jsonl") if (self.dir / "depth.jsonl").is_file() else []
        )
        # the other UUVs' depths (--uuv-depth-key ID=KEY): (key, samples)
        self.uuv_depths = [
            (key, depth_to_send(uuv_files(self.dir, uuv_id).depth))
            for uuv_id, key in args.uuv_depth_key
        ]
        videos = sorted(p for p in self.dir.glob("video.*") if p.is_file())
        self.video = videos[0] if videos and not args.no_video else None
        self.frames = (
            read_table(self.dir / "video_frames.csv", ("frame", "t")) if self.video else None
        )
        starts = [self.tlog[0][0]] + [self.depth[0][0]] * bool(self.depth)
        ends = [self.tlog[-1][0]] + [self.depth[-1][0]] * bool(self.depth)  # in arrival order
        if self.frames is not None:
            starts.append(float(self.frames["t"][0]))
            ends.append(float(self.frames["t"][-1]))
        self.t_start, self.t_end = min(starts), max(ends)
        self.stop = threading.Event()
        self.counts = {"mavlink": 0, "depth": 0, "gps_input": 0}

    def _send_tlog(self, conn, shift: float) -> None:
        cuts = Cuts(self.args.cut, "mavlink")
        for t, msg in self.tlog:
            if not _sleep_until(t + shift, self.stop):
                return
            if cuts.skip(t - self.t_start):
                continue
            conn.write(frame_bytes(msg, shift))
            self.counts["mavlink"] += 1

    def _send_depth(self, shift: float, session, key: str, samples) -> None:
        cuts = Cuts(self.args.cut, "depth")
        for t_send, t, depth in samples:
            if not _sleep_until(t_send + shift, self.stop):
                return
            if cuts.skip(t_send - self.t_start):
                continue
            put_json(key, {"t": t + shift, "depth_m": depth}, session)
            self.counts["depth"] += 1

    def _listen_uuv(self, transport, out) -> None:
        """Every GPS_INPUT that reaches ``--uuv-listen``, stamped with its arrival (:mod:`~groundstation.mavlink.
        transport`'s ``t_received``: a UDP datagram's as the kernel received it, however late this thread reads it);
        and, as the UUV's autopilot does, a HEARTBEAT a second back to its sender (so skyfix hears an autopilot)."""
        mavlink = mavutil().mavlink
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        autopilot = mavlink.MAVLink(
            None, srcSystem=UUV_SYSID, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1
        )
        next_beat = 0.0
        while not self.stop.is_set():
            if transport.peer_known and time.monotonic() >= next_beat:
                next_beat = time.monotonic() + HEARTBEAT_PERIOD_S
                beat = autopilot.heartbeat_encode(
                    mavlink.MAV_TYPE_SUBMARINE,
                    mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                    0,
                    0,
                    mavlink.MAV_STATE_ACTIVE,
                )
                try:
                    transport.write(beat.pack(autopilot))
                except OSError:  # a TCP peer went away: the read below finds out
                    pass
            if not select.select(transport.filenos(), [], [], 0.2)[0]:
                continue
            try:
                data = transport.read()
            except OSError:  # a TCP peer went away (tcpin: listens again): no busy loop meanwhile
                self.stop.wait(0.2)
                continue
            for msg in parser.parse_buffer(data) or []:
                if msg.get_type() != "GPS_INPUT":
                    continue
                if transport.datagrams:
                    transport.answer_last_sender()
                rec = {
                    "event": "gps_input",
                    "t_recv": transport.t_received,
                    "sysid": msg.get_srcSystem(),
                    "compid": msg.get_srcComponent(),
                    **msg.to_dict(),
                }
                rec.pop("mavpackettype", None)
                out.write(json.dumps(rec) + "\n")
                out.flush()
                self.counts["gps_input"] += 1

    def run(self) -> int:
        args = self.args
        shift = time.time() + args.lead_s - self.t_start if args.shift_s is None else args.shift_s
        if self.t_start + shift < time.time():
            print(
                f"skyfix replay: error: --shift-s {args.shift_s}: the session would have started "
                f"{time.time() - self.t_start - shift:.1f} s ago",
                file=sys.stderr,
            )
            return 2
        out = open(args.uuv_log, "a") if args.uuv_log else sys.stdout  # noqa: SIM115 - closed in finally
        print(
            json.dumps(
                {
                    "event": "start",
                    "session": str(self.dir),
                    "shift_s": shift,
                    "t_start": self.t_start + shift,
                    "t_end": self.t_end + shift,
                }
            ),
            flush=True,
        )
        links = [connect(args.mavlink_out, input=False)]
        if args.uuv_listen:
            try:
                links.append(open_transport(args.uuv_listen))
            except OSError as e:
                links[0].close()
                raise LinkError(f"--uuv-listen {args.uuv_listen!r}: cannot open: {e}") from None
        session = open_session(
            args.zenoh_connect or (), args.zenoh_listen or (), config_file=args.zenoh_config
        )
        threads = [
            threading.Thread(
                target=self._send_tlog, args=(links[0], shift), name="tlog", daemon=True
            )
        ]
        depths = [(args.depth_key, self.depth)] * bool(args.depth_key) + self.uuv_depths
        threads += [
            threading.Thread(
                target=self._send_depth,
                args=(shift, session, key, samples),
                name=f"depth {key}",
                daemon=True,
            )
            for key, samples in depths
        ]
        if args.uuv_listen:
            threads.append(
                threading.Thread(
                    target=self._listen_uuv, args=(links[1], out), name="uuv", daemon=True
                )
            )
        if self.video is not None:
            t_first = float(self.frames["t"][0])
            t0 = t_first + shift + args.video_delay_ms / 1000.0
            cuts = Cuts(args.cut, "video")
            # as BlueOS's camera manager publishes it
            zenoh_out = args.video_out.startswith("zenoh:")
            threads.append(
                threading.Thread(
                    target=partial(publish_video, session=session) if zenoh_out else send_video,
                    args=(
                        self.video,
                        args.video_out.removeprefix("zenoh:"),
                        t0,
                        self.stop,
                        lambda t_s, key: cuts.skip(t_first - self.t_start + t_s, key),
                    ),
                    name="video",
                    daemon=True,
                )
            )
        try:
            for th in threads:
                th.start()
            t_stop = self.t_end + shift + args.tail_s
            if args.duration_s is not None:
                t_stop = min(t_stop, time.time() + args.duration_s)
            _sleep_until(t_stop, self.stop)
        except KeyboardInterrupt:
            pass
        finally:
            self.stop.set()
            for th in threads:
                th.join(2.0)
            for link in links:
                link.close()
            session.close()
            print(json.dumps({"event": "end", **self.counts}), flush=True)
            if out is not sys.stdout:
                out.close()
        if args.uuv_listen and self.counts["gps_input"] == 0:
            print(
                f"skyfix replay: no GPS_INPUT came back on {args.uuv_listen} (is skyfix run's --gps-input "
                "pointed there?)",
                file=sys.stderr,
            )
            return 1
        return 0


def replay(args: argparse.Namespace) -> int:
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s: %(message)s"
    )
    return Replay(args).run()


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help, description=__doc__.split("\n\n")[0])
    p.add_argument("session", help="session directory (format v1)")
    p.add_argument(
        "--mavlink-out", default="udpout:127.0.0.1:14550", help="where the UAV's MAVLink goes"
    )
    p.add_argument(
        "--video-out",
        default="udp://127.0.0.1:5600",
        help="where the video goes: udp://host:port (MPEG-TS), rtp://host:port (RTP) or zenoh:KEY "
        "(foxglove.CompressedVideo on Zenoh, as BlueOS's camera manager publishes it)",
    )
    p.add_argument("--no-video", action="store_true", help="do not stream the video")
    p.add_argument(
        "--video-delay-ms",
        type=float,
        default=0.0,
        help="send each frame this long after its exposure: a camera with this glass-to-first-packet latency",
    )
    p.add_argument(
        "--zenoh-connect", action="append", metavar="ENDPOINT", help="Zenoh endpoint to connect to"
    )
    p.add_argument(
        "--zenoh-listen", action="append", metavar="ENDPOINT", help="Zenoh endpoint to listen on"
    )
    p.add_argument(
        "--zenoh-config",
        help="Zenoh JSON5 config file (deploy/zenoh/*.json5); endpoints above are added",
    )
    p.add_argument(
        "--depth-key",
        default="uuv/depth",
        help="Zenoh key the depth is published on ('' for none: "
        "another replay of the same dive publishes it)",
    )
    p.add_argument(
        "--uuv-depth-key",
        action="append",
        type=parse_uuv_key,
        default=[],
        metavar="ID=KEY",
        help="also publish the session's UUV ID's depth (uuvs/ID/depth.jsonl) on KEY (repeatable)",
    )
    p.add_argument(
        "--uuv-listen",
        default="udpin:127.0.0.1:14660",
        help="UUV-side endpoint logging GPS_INPUT ('' for none)",
    )
    p.add_argument(
        "--uuv-log", help="file the GPS_INPUT JSON lines are appended to (default stdout)"
    )
    p.add_argument(
        "--lead-s", type=float, default=1.0, help="delay before the session's first message"
    )
    p.add_argument(
        "--shift-s",
        type=float,
        help="shift the session's times by exactly this (UNIX s − session s) "
        "instead of now + --lead-s − its first time: replays of sessions recorded at once (two drones "
        "over one UUV) given the same shift play in step",
    )
    p.add_argument(
        "--tail-s", type=float, default=1.0, help="keep listening this long after the session ends"
    )
    p.add_argument("--duration-s", type=float, help="stop after this many seconds")
    p.add_argument(
        "--cut",
        action="append",
        type=parse_cut,
        metavar="INPUT:START_S:DURATION_S",
        help="leave out mavlink, depth or video from START_S for DURATION_S seconds after the session's "
        "start (a link dropping out; repeatable)",
    )
    p.set_defaults(func=replay)
