"""``--record DIR``: the live run written as a session directory (format v1) as it goes.

``session.toml`` (version 1 and the calibration's tables) is written first, and
again with ``[tracker] init_bbox``/``init_t`` at the first fix: the tracker's box on
that frame, so ``skyfix process`` starts the tracker where the live run had it;
``uav.tlog`` gets every good MAVLink frame from the UAV with its receive time,
``depth.jsonl`` every accepted depth sample (``t`` the UUV's own stamp, or the
arrival minus the depth latency when the source has none, and ``t_recv`` its
arrival on the station clock), ``positions.csv`` every fix, ``track.csv`` the
tracked pixel of every frame (empty when there is no fix), and
``video.ts`` + ``video_frames.csv`` the received frames (H.264 in MPEG-TS, encoded
in-process, each frame's timestamp its exposure time, so a replay keeps the real
pacing and the offline reader finds each frame's row). Every file is append-only and flushed at least
once a second; MPEG-TS stays readable when cut off, so a crash loses at most the
last second and never corrupts what is already written. When the encoder falls
behind, frames are left out of the recording (counted), and ``video_frames.csv``
lists only the frames that were encoded.
"""

from __future__ import annotations

import asyncio
import csv
import json
import logging
import os
import queue
import struct
import threading
import time
import tomllib
from fractions import Fraction
from pathlib import Path

import av

from localizer.fix import Fix

from ..positions import COLUMNS, format_row

log = logging.getLogger("skyfix.record")

TICK = Fraction(1, 90000)  # MPEG-TS timestamp unit, seconds
CALIBRATION_TABLES = ("camera", "mount", "water", "tracker", "uncertainty", "timing")


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise ValueError(f"cannot write {value!r} to session.toml")


def session_toml(calibration: dict) -> str:
    """session.toml text: ``version = 1`` and the calibration's tables (scalars and lists)."""
    lines = ["version = 1"]
    for name in CALIBRATION_TABLES:
        if name in calibration:
            lines += ["", f"[{name}]"] + [f"{k} = {_toml_value(v)}" for k, v in calibration[name].items()]
    return "\n".join(lines) + "\n"


class VideoWriter:
    """Frames → H.264 (libx264 in-process, PyAV) in MPEG-TS, ``frames.csv`` a row per encoded frame.

    One thread owns the encoder and both files: it takes frames from a queue, stamps
    each with its exposure time (90 kHz ticks from the first frame's), encodes it, and
    flushes ``frames.csv`` at least once a second. A frame not later than the one
    before (a stream reconnected on another clock) is left out and counted as dropped.
    """

    def __init__(self, path: Path, frames_csv: Path, size: tuple[int, int], queue_len: int = 30):
        self.path = path
        self.frames_csv = frames_csv
        self.size = size
        self.written = 0
        self.dropped = 0
        self.error: str | None = None
        self._queue: queue.Queue = queue.Queue(maxsize=queue_len)
        self._thread = threading.Thread(target=self._write, name="record-video", daemon=True)
        self._thread.start()

    def put(self, t_unix: float, image) -> None:
        try:
            self._queue.put_nowait((t_unix, image))
        except queue.Full:
            self.dropped += 1

    def _open(self):
        container = av.open(str(self.path), "w", format="mpegts")
        stream = container.add_stream("libx264", options={"preset": "ultrafast", "tune": "zerolatency"})
        stream.width, stream.height = self.size
        stream.pix_fmt = "yuv420p"
        stream.codec_context.time_base = TICK
        stream.time_base = TICK
        return container, stream

    def _write(self) -> None:
        container, stream = self._open()
        t0, t_last, last_pts = None, None, -1
        next_flush = time.monotonic() + 1.0
        with open(self.frames_csv, "w", newline="") as frames:
            rows = csv.writer(frames)
            rows.writerow(("frame", "t"))
            try:
                while True:
                    try:
                        item = self._queue.get(timeout=1.0)
                    except queue.Empty:
                        frames.flush()
                        continue
                    if item is None:
                        break
                    if self.error is not None:
                        continue  # drained: the encoder failed
                    t, image = item
                    if t0 is not None and t <= t_last:  # a reconnected stream's clock went back: out of order
                        self.dropped += 1
                        continue
                    t0, t_last = (t if t0 is None else t0), t
                    frame = av.VideoFrame.from_ndarray(image, format="bgr24")
                    frame.pts = last_pts = max(last_pts + 1, round((t - t0) / TICK))
                    frame.time_base = TICK
                    try:
                        container.mux(stream.encode(frame))
                    except (av.error.FFmpegError, ValueError) as e:
                        self.error = f"{self.path}: {e}"
                        log.warning("record: video encoder failed, no more video recorded: %s", self.error)
                        continue
                    rows.writerow((self.written, f"{t:.6f}"))
                    self.written += 1
                    if time.monotonic() >= next_flush:
                        frames.flush()
                        next_flush = time.monotonic() + 1.0
            finally:
                try:
                    container.mux(stream.encode(None))
                finally:
                    container.close()

    def close(self) -> None:
        self._queue.put(None)
        self._thread.join(10.0)


class Recorder:
    """Worker and sink writing the session; see the module docstring."""

    def __init__(self, directory: str, cal_source: str, video_size: tuple[int, int] | None = None,
                 depth_latency_s: float = 0.0):
        self.dir = Path(directory)
        if self.dir.exists() and not self.dir.is_dir():
            raise FileExistsError(f"--record {directory}: exists and is not a directory")
        if self.dir.exists() and any(self.dir.iterdir()):
            raise FileExistsError(f"--record {directory}: exists and is not empty (a recording is never overwritten)")
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise OSError(f"--record {directory}: cannot create it: {e.strerror}") from None
        # [tracker] is the live run's own: the first frame the target was tracked on (see on_fix), not the
        # calibration file's, whose init_t belongs to another recording
        self._calibration = {k: v for k, v in tomllib.loads(Path(cal_source).read_text()).items() if k != "tracker"}
        self._write_toml()
        self._track = open(self.dir / "track.csv", "a", newline="")  # noqa: SIM115
        self._track_csv = csv.writer(self._track)
        self._track_csv.writerow(("t", "u", "v"))
        # append-only files, open for the whole run and closed when the worker ends
        self._tlog = open(self.dir / "uav.tlog", "ab")  # noqa: SIM115
        self._depth = open(self.dir / "depth.jsonl", "a")  # noqa: SIM115
        self._positions = open(self.dir / "positions.csv", "a", newline="")  # noqa: SIM115
        self._pos_csv = csv.writer(self._positions)
        self._pos_csv.writerow(COLUMNS)
        # started now, not at the first frame: opening the encoder takes time the event loop cannot spare
        self._video = VideoWriter(self.dir / "video.ts", self.dir / "video_frames.csv", video_size) if video_size else None
        self.depth_latency_s = depth_latency_s
        self.mavlink_frames = 0
        self.depth_samples = 0
        self.fixes = 0

    def on_mavlink(self, msg, t_recv: float) -> None:
        self._tlog.write(struct.pack(">Q", int(t_recv * 1e6)) + msg.get_msgbuf())
        self.mavlink_frames += 1

    def on_depth(self, t_uuv: float | None, depth_m: float, t_recv: float) -> None:
        t = t_recv - self.depth_latency_s if t_uuv is None else t_uuv
        self._depth.write(json.dumps({"t": t, "depth_m": depth_m, "t_recv": t_recv}) + "\n")
        self.depth_samples += 1

    def on_frame(self, frame) -> None:
        """A received frame (of the ``video_size`` given at the start)."""
        self._video.put(frame.t_unix, frame.image)

    def _write_toml(self) -> None:
        """session.toml, replaced atomically."""
        tmp = self.dir / "session.toml.partial"
        tmp.write_text(session_toml(self._calibration))
        os.replace(tmp, self.dir / "session.toml")

    def on_fix(self, fix: Fix, info) -> None:
        self._pos_csv.writerow(format_row(fix))
        ok = fix.ok
        self._track_csv.writerow((f"{fix.t_unix:.6f}", f"{fix.u:.3f}" if ok else "", f"{fix.v:.3f}" if ok else ""))
        if ok and "tracker" not in self._calibration and getattr(info, "box", None) is not None:
            self._calibration["tracker"] = {"init_bbox": list(info.box), "init_t": fix.t_unix}
            self._write_toml()
        self.fixes += 1

    def flush(self) -> None:
        for f in (self._tlog, self._depth, self._positions, self._track):
            f.flush()

    async def run(self) -> None:
        try:
            while True:
                await asyncio.sleep(1.0)
                self.flush()
        finally:
            self.flush()
            if self._video:
                await asyncio.to_thread(self._video.close)
            for f in (self._tlog, self._depth, self._positions, self._track):
                f.close()

    def status(self) -> dict:
        out = {"dir": str(self.dir), "mavlink_frames": self.mavlink_frames, "depth_samples": self.depth_samples,
               "fixes": self.fixes}
        if self._video:
            out.update(video_frames=self._video.written, video_dropped=self._video.dropped,
                       video_error=self._video.error)
        return out
