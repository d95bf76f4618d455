"""``--record DIR``: the live run written as a session directory (format v1) as it goes.

``session.toml`` (version 1 and the calibration's tables) is written first, and
again with ``[tracker] init_bbox``/``init_t`` at the first fix: the tracker's box on
that frame, so ``skyfix process`` starts the tracker where the live run had it; and
again whenever what the run measured and used for time changes (checked once a
second: ``timing()``, e.g. the link delay TIMESYNC measured and since when, the video
latency in use with its source and sigma), written into ``[timing]``'s recorded keys
(:data:`RECORDED_TIMING`; those of the calibration file, another recording's, are dropped);
``uav.tlog`` gets every good MAVLink frame from the UAV with its receive time,
``depth.jsonl`` every accepted depth sample (``t`` the UUV's own stamp, or the station time
ArduSub's was mapped to from its boot clock, ``t_recv`` its arrival on the station clock, and
what the service used with it: ``source``, ``sigma_m`` and ``vspeed_mps`` where known),
``positions.csv`` every fix, ``track.csv`` the
tracked pixel of every frame (empty when there is no fix), and
``video.ts`` + ``video_frames.csv`` the received frames (H.264 in MPEG-TS, encoded
in-process, each frame's timestamp its exposure time, so a replay keeps the real
pacing and the offline reader finds each frame's row). A run of several UUVs (``[[uuv]]``): the first
UUV's depth, fixes, track and ``[tracker]`` are the session's own files, each other's are in ``uuvs/<id>/``
(``depth.jsonl``, ``positions.csv``, ``track.csv``, and ``uuv.toml`` with its ``[tracker]``), as the session
reader reads them. Every file is append-only and flushed at least
once a second; MPEG-TS stays readable when cut off, so a crash loses at most the
last second and never corrupts what is already written.

One thread owns every file: it opens, writes, flushes and closes them (and rewrites
session.toml); the event loop only queues what is to be written (:data:`QUEUE_ITEMS`
records, :data:`QUEUE_FRAMES` video frames; beyond, the item is left out and counted in
``dropped``/``video_dropped``), so no disk write ever blocks the loop, and a stop asks
the thread to finish and close, never closes a file under it. ``video_frames.csv`` lists
only the frames that were encoded. Times only increase in every table: a frame or fix not later
than the one before (a reconnected stream on another clock; ``--video-latency-ms auto``
applying its estimate, which moves the frames' times back by it) is left out and counted. A write that fails (a full disk) stops the recording
with one log line and ``error`` in the status; the service goes on without it.
"""

from __future__ import annotations

import asyncio
import csv
import itertools
import json
import logging
import math
import os
import queue
import threading
import time
import tomllib
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path

import av

from groundstation.runtime.threads import failure_kind, in_thread
from groundstation.session.positions import COLUMNS, format_row
from groundstation.session.read import PRIMARY_UUV, UUV_TOML, UUVS_DIR
from groundstation.session.tlog import tlog_record
from localizer.depth import DepthSample
from localizer.fix import Fix

log = logging.getLogger("skyfix.record")

TICK = Fraction(1, 90000)  # MPEG-TS timestamp unit, seconds
CALIBRATION_TABLES = ("camera", "mount", "water", "tracker", "uncertainty", "timing")
QUEUE_ITEMS = 20000  # records waiting for the writer (MAVLink frames, depth samples, fixes): ~2 min of telemetry
QUEUE_FRAMES = 30  # video frames waiting for the encoder
FLUSH_S = 1.0
# a stop waits this long for the writer to close its files, then leaves it to finish
CLOSE_WAIT_S = 0.5
#: ``[timing]`` keys that say what a live run measured and used (localizer.calibration.Timing)
RECORDED_TIMING = (
    "mavlink_latency_measured_s",
    "mavlink_latency_measured_from_t",
    "video_latency_s",
    "video_latency_source",
    "video_latency_sigma_s",
    "video_latency_from_t",
)
TIMING_CHECK_S = 1.0


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return repr(int(value))
    if isinstance(value, float):  # numpy's floats too, written as plain numbers
        return repr(float(value))
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise ValueError(f"cannot write {value!r} to session.toml")


def session_toml(calibration: dict) -> str:
    """session.toml text: ``version = 1`` and the calibration's tables (scalars and lists)."""
    return "version = 1\n" + _tables(calibration)


def _tables(tables: dict) -> str:
    """TOML text of ``tables``' tables of :data:`CALIBRATION_TABLES` (scalars and lists), each after a blank line."""
    lines = []
    for name in CALIBRATION_TABLES:
        if name in tables:
            lines += ["", f"[{name}]"] + [
                f"{k} = {_toml_value(v)}" for k, v in tables[name].items()
            ]
    return "\n".join(lines) + "\n"


class VideoWriter:
    """Frames → H.264 (libx264 in-process, PyAV) in MPEG-TS, ``frames.csv`` a row per encoded frame.

    Used by one thread only (the recorder's): :meth:`write` stamps each frame with its exposure
    time (90 kHz ticks from the first frame's) and encodes it. A frame not later than the one
    before (a stream reconnected on another clock) is left out and counted as dropped.
    """

    def __init__(self, path: Path, frames_csv: Path, size: tuple[int, int]):
        self.path = path
        self.size = size
        self.written = 0
        self.dropped = 0
        self._container = av.open(str(path), "w", format="mpegts")
        self._stream = stream = self._container.add_stream(
            "libx264", options={"preset": "ultrafast", "tune": "zerolatency"}
        )
        stream.width, stream.height = size
        stream.pix_fmt = "yuv420p"
        stream.codec_context.time_base = TICK
        stream.time_base = TICK
        self._frames = open(frames_csv, "w", newline="")  # noqa: SIM115 - closed in close()
        self._rows = csv.writer(self._frames)
        self._rows.writerow(("frame", "t"))
        self._t0: float | None = None
        self._t_last: float | None = None
        self._last_pts = -1

    def write(self, t_unix: float, image) -> None:
        if (
            self._t0 is not None and t_unix <= self._t_last
        ):  # a reconnected stream's clock went back: out of order
            self.dropped += 1
            return
        self._t0 = t_unix if self._t0 is None else self._t0
        self._t_last = t_unix
        frame = av.VideoFrame.from_ndarray(image, format="bgr24")
        frame.pts = self._last_pts = max(self._last_pts + 1, round((t_unix - self._t0) / TICK))
        frame.time_base = TICK
        self._container.mux(self._stream.encode(frame))
        self._rows.writerow((self.written, f"{t_unix:.6f}"))
        self.written += 1

    def flush(self) -> None:
        self._frames.flush()

    def close(self) -> None:
        try:
            self._container.mux(self._stream.encode(None))
        finally:
            self._container.close()
            self._frames.close()


class UuvRecord:
    """One UUV's part of the recording: its depth samples (:meth:`on_depth`, a depth reader's listener), its fixes
    and tracked pixels and its ``[tracker]`` at its first fix (:meth:`on_fix`, a sink of its pipeline). The first
    UUV's go to the session's own files; each other's to ``uuvs/<id>/`` (``uuv.toml`` holding its ``[tracker]``)."""

    def __init__(self, recorder: Recorder, uuv_id: str, folder: Path):
        self.recorder = recorder
        self.id = uuv_id
        self.folder = folder
        self.depth_samples = 0
        self.fixes = 0
        self.tracker: dict | None = None  # init_bbox and init_t: the box of its first fix
        self._last_fix_t: float | None = None

    def on_depth(self, sample: DepthSample, t_recv: float) -> None:
        rec = {"t": sample.t, "depth_m": sample.depth_m, "t_recv": t_recv, "source": sample.source}
        rec |= {
            k: v
            for k, v in (("sigma_m", sample.sigma_m), ("vspeed_mps", sample.vspeed_mps))
            if math.isfinite(v)
        }
        self.depth_samples += self.recorder._put(("depth", (self.folder, json.dumps(rec) + "\n")))

    def on_fix(self, fix: Fix, info) -> None:
        if self._last_fix_t is not None and not fix.t_unix > self._last_fix_t:
            # frames' times went back (auto applying its first latency): left out, as the video writer does
            self.recorder.dropped += 1
            return
        self._last_fix_t = fix.t_unix
        ok = fix.ok
        track = (f"{fix.t_unix:.6f}", f"{fix.u:.3f}" if ok else "", f"{fix.v:.3f}" if ok else "")
        self.fixes += self.recorder._put(("fix", (self.folder, format_row(fix), track)))
        if ok and self.tracker is None and getattr(info, "box", None) is not None:
            self.tracker = {"init_bbox": list(info.box), "init_t": fix.t_unix}
            self.recorder._tracker_found(self)


def new_recording(parent, t_unix: float) -> Path:
    """A new, empty folder for one start's recording in ``parent`` (``--recordings``; created if missing): named by
    ``t_unix`` as UTC ``YYYYmmdd-HHMMSS``, ``-2``, ``-3``, … after it when taken (made with one ``mkdir`` each, so two
    starts in the same second never share one). :class:`OSError` naming ``parent`` when it cannot be made."""
    parent = Path(parent)
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime(t_unix))
    try:
        parent.mkdir(parents=True, exist_ok=True)
        for n in itertools.count(1):
            folder = parent / (stamp if n == 1 else f"{stamp}-{n}")
            try:
                folder.mkdir()
            except FileExistsError:
                continue
            return folder
    except OSError as e:
        raise OSError(
            f"--recordings {parent}: cannot make a folder in it: {e.strerror or e}"
        ) from None


class Recorder:
    """Worker writing the session (see the module docstring); :meth:`of` is each UUV's part of it."""

    def __init__(
        self,
        directory: str,
        cal_source: str,
        video_size: tuple[int, int] | None = None,
        timing: Callable[[], dict] | None = None,
        uuv_ids: tuple[str, ...] = (PRIMARY_UUV,),
    ):
        self.dir = Path(directory)
        if self.dir.exists() and not self.dir.is_dir():
            raise FileExistsError(f"--record {directory}: exists and is not a directory")
        if self.dir.exists() and any(self.dir.iterdir()):
            raise FileExistsError(
                f"--record {directory}: exists and is not empty (a recording is never overwritten; "
                "--recordings PARENT records each start into a new folder of its own)"
            )
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise OSError(f"--record {directory}: cannot create it: {e.strerror}") from None
        # [tracker] is the live run's own: the first frame the target was tracked on (see on_fix), not the
        # calibration file's, whose init_t belongs to another recording
        self._calibration = {
            k: v for k, v in tomllib.loads(Path(cal_source).read_text()).items() if k != "tracker"
        }
        if "timing" in self._calibration:  # another recording's measurements are not this one's
            self._calibration["timing"] = {
                k: v for k, v in self._calibration["timing"].items() if k not in RECORDED_TIMING
            }
        self.timing = timing or dict
        self._write_toml(session_toml(self._calibration))
        self.video_size = video_size
        # the first UUV is the session's own; each other has its folder under uuvs/ (session/read.py reads them)
        self._uuvs = {
            uuv_id: UuvRecord(self, uuv_id, self.dir if i == 0 else self.dir / UUVS_DIR / uuv_id)
            for i, uuv_id in enumerate(uuv_ids)
        }
        self.first = self._uuvs[uuv_ids[0]]
        for uuv in list(self._uuvs.values())[1:]:
            uuv.folder.mkdir(parents=True)
        self.mavlink_frames = 0
        self.dropped = 0
        self.video_dropped = 0
        self.error: str | None = None
        self._video: VideoWriter | None = None
        self._queue: queue.Queue = queue.Queue(maxsize=QUEUE_ITEMS)
        self._frames_queued = 0  # frames in the queue (written on the loop, lowered by the writer)
        self._frames_lock = threading.Lock()
        self._closing = threading.Event()
        # started now, not at the first frame: opening the encoder takes time the event loop cannot spare
        self._thread = threading.Thread(target=self._write, name="record", daemon=True)
        self._thread.start()

    # -- the event loop's side: queue only ---------------------------------------------------------------
    def _put(self, item) -> bool:
        if self.error is not None:
            return False
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.dropped += 1
            return False
        return True

    def on_mavlink(self, msg, t_recv: float) -> None:
        self.mavlink_frames += self._put(("tlog", tlog_record(int(t_recv * 1e6), msg.get_msgbuf())))

    def on_frame(self, frame) -> None:
        """A received frame (of the ``video_size`` given at the start)."""
        with self._frames_lock:
            if self._frames_queued >= QUEUE_FRAMES:
                self.video_dropped += 1
                return
            self._frames_queued += 1
        if not self._put(("frame", (frame.t_unix, frame.image))):
            with self._frames_lock:
                self._frames_queued -= 1

    def of(self, uuv_id: str) -> UuvRecord:
        """The part of the recording of the UUV ``uuv_id``."""
        return self._uuvs[uuv_id]

    @property
    def depth_samples(self) -> int:
        return sum(u.depth_samples for u in self._uuvs.values())

    @property
    def fixes(self) -> int:
        return sum(u.fixes for u in self._uuvs.values())

    def _session_toml(self) -> str:
        tracker = {"tracker": self.first.tracker} if self.first.tracker else {}
        return session_toml(self._calibration | tracker)

    def _tracker_found(self, uuv: UuvRecord) -> None:
        """A UUV's first fix: its [tracker] written (session.toml's for the first UUV, its uuv.toml for another)."""
        if uuv is self.first:
            self._put(("toml", (self.dir / "session.toml", self._session_toml())))
        else:
            self._put(
                ("toml", (uuv.folder / UUV_TOML, _tables({"tracker": uuv.tracker}).lstrip("\n")))
            )

    def _record_timing(self) -> None:
        """``[timing]``'s recorded keys from ``timing()``; session.toml rewritten when they changed."""
        table = self._calibration.get("timing", {})
        recorded = {k: v for k, v in self.timing().items() if v is not None}
        if recorded != {k: table[k] for k in RECORDED_TIMING if k in table}:
            self._calibration["timing"] = {
                k: v for k, v in table.items() if k not in RECORDED_TIMING
            } | recorded
            self._put(("toml", (self.dir / "session.toml", self._session_toml())))

    async def run(self) -> None:
        try:
            while True:
                self._record_timing()
                await asyncio.sleep(TIMING_CHECK_S)
        finally:
            self._record_timing()  # what the run ended with
            self._closing.set()
            await in_thread(self._thread.join, CLOSE_WAIT_S, name="record close")
            if self._thread.is_alive():
                log.warning(
                    "record: the writer was still busy %g s after the stop (%d items queued); it finishes "
                    "on its own unless the process ends first",
                    CLOSE_WAIT_S,
                    self._queue.qsize(),
                )

    # -- the writer thread: owns every file ----------------------------------------------------------------
    def _write_toml(self, text: str, path: Path | None = None) -> None:
        """session.toml (or a UUV's uuv.toml), replaced atomically."""
        path = path or self.dir / "session.toml"
        tmp = path.with_name(path.name + ".partial")
        tmp.write_text(text)
        os.replace(tmp, path)

    def _write(self) -> None:
        files = []
        try:
            tlog = open(self.dir / "uav.tlog", "ab")  # noqa: SIM115 - closed below
            files.append(tlog)
            depth, pos_csv, track_csv = {}, {}, {}  # per UUV folder
            for folder in (u.folder for u in self._uuvs.values()):
                depth[folder] = open(folder / "depth.jsonl", "a")  # noqa: SIM115
                positions = open(folder / "positions.csv", "a", newline="")  # noqa: SIM115
                track = open(folder / "track.csv", "a", newline="")  # noqa: SIM115
                files += [depth[folder], positions, track]
                pos_csv[folder], track_csv[folder] = csv.writer(positions), csv.writer(track)
                pos_csv[folder].writerow(COLUMNS)
                track_csv[folder].writerow(("t", "u", "v"))
            if self.video_size:
                self._video = VideoWriter(
                    self.dir / "video.ts", self.dir / "video_frames.csv", self.video_size
                )
            next_flush = time.monotonic() + FLUSH_S
            while True:
                try:
                    kind, data = self._queue.get(timeout=0.1)
                except queue.Empty:
                    if self._closing.is_set():
                        break
                    kind = None
                if kind == "tlog":
                    tlog.write(data)
                elif kind == "depth":
                    depth[data[0]].write(data[1])
                elif kind == "fix":
                    pos_csv[data[0]].writerow(data[1])
                    track_csv[data[0]].writerow(data[2])
                elif kind == "toml":
                    self._write_toml(data[1], data[0])
                elif kind == "frame":
                    with self._frames_lock:
                        self._frames_queued -= 1
                    self._video.write(*data)
                if time.monotonic() >= next_flush:
                    for f in files:
                        f.flush()
                    if self._video:
                        self._video.flush()
                    next_flush = time.monotonic() + FLUSH_S
        except Exception as e:  # noqa: BLE001 - a full disk, an encoder error or a bug: the recording stops
            self.error = f"{failure_kind(e)}: {e}"
            log.error("record: stopped, nothing more is recorded: %s", self.error)
        finally:
            for close in [f.close for f in files] + ([self._video.close] if self._video else []):
                try:
                    close()
                except Exception as e:  # noqa: BLE001 - closing what can be closed
                    log.warning("record: closing: %s", e)

    def status(self) -> dict:
        out = {
            "dir": str(self.dir),
            "mavlink_frames": self.mavlink_frames,
            "depth_samples": self.depth_samples,
            "fixes": self.fixes,
            "dropped": self.dropped,
            "error": self.error,
        }
        if self.video_size:
            video = self._video
            out.update(
                video_frames=video.written if video else 0,
                video_dropped=self.video_dropped + (video.dropped if video else 0),
            )
        return out
