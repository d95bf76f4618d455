"""Reading a session directory (format version 1) into calibration, telemetry and tables.

Every problem is a :class:`SessionError` whose one-line message names the file,
the line or key, and the offending value. Recoverable oddities (undecodable
MAVLink frames, messages from other systems, a truncated last line of a log that
was being written when power went) are kept as warnings on the session.

A session may hold several UUVs (:func:`uuv_ids`): the first, :data:`PRIMARY_UUV`, is the one
format v1 describes (``depth.jsonl``, ``truth.csv``, ``track.csv``, ``session.toml``'s
``[tracker]``); each other has a folder ``uuvs/<id>/`` with its own ``depth.jsonl``,
``truth.csv``, ``track.csv`` and ``uuv.toml`` (its ``[tracker]`` table). ``load_session(path,
uuv=id)`` reads the session as that UUV's: its depth, truth, track and first box with the UAV's
telemetry and calibration, so everything that processes a session processes it for that UUV.
"""

from __future__ import annotations

import copy
import csv
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from groundstation.mavlink.ingest import ingest, uav_system
from groundstation.session import SessionError
from groundstation.session.depth import read_depth
from groundstation.session.tlog import read_tlog
from groundstation.video.file import Video, open_video
from localizer.calibration import Calibration, ConfigError, Timing
from localizer.depth import SOURCE_WORDS
from localizer.telemetry import Telemetry

SUPPORTED_VERSION = 1
_NEEDED_FOR_SOURCE = {
    "gimbal_device": "GIMBAL_DEVICE_ATTITUDE_STATUS",
    "mount_orientation": "MOUNT_ORIENTATION",
}
PRIMARY_UUV = "uuv1"  # the id of the UUV whose records are the session's own files
UUVS_DIR = "uuvs"  # the folder of the other UUVs' folders, one per id
# in a UUV's folder: its [tracker] table (init_bbox, init_t), as session.toml's
UUV_TOML = "uuv.toml"


@dataclass(frozen=True)
class UuvFiles:
    """Where one UUV's records lie in a session: the session's own files for :data:`PRIMARY_UUV`, ``uuvs/<id>/``
    for each other (the same names; its ``[tracker]`` table in ``uuv.toml`` instead of ``session.toml``)."""

    id: str
    folder: Path
    tracker_toml: Path  # the TOML file whose [tracker] table holds its first box

    @property
    def depth(self) -> Path:
        return self.folder / "depth.jsonl"

    @property
    def truth(self) -> Path:
        return self.folder / "truth.csv"

    @property
    def track(self) -> Path:
        return self.folder / "track.csv"

    @property
    def truth_waves(self) -> Path:
        """A generated session's waves' own error (``skyfix sim`` with ``[waves]``: ``t,wave_dn_m,wave_de_m``)."""
        return self.folder / "truth_waves.csv"


def uuv_ids(path) -> tuple[str, ...]:
    """The ids of a session's UUVs: :data:`PRIMARY_UUV` first, then the folders of ``uuvs/`` by name."""
    others = Path(path) / UUVS_DIR
    found = sorted(p.name for p in others.iterdir() if p.is_dir()) if others.is_dir() else []
    if PRIMARY_UUV in found:
        raise SessionError(
            f"{others / PRIMARY_UUV}: {PRIMARY_UUV} is the session's own UUV (its files are the "
            "session's), not a folder of uuvs/"
        )
    return (PRIMARY_UUV, *found)


def uuv_files(path, uuv_id: str = PRIMARY_UUV) -> UuvFiles:
    """Where the records of the session's UUV ``uuv_id`` lie; :class:`SessionError` for an id it does not hold."""
    path = Path(path)
    if uuv_id == PRIMARY_UUV:
        return UuvFiles(uuv_id, path, path / "session.toml")
    ids = uuv_ids(path)
    if uuv_id not in ids:
        raise SessionError(
            f"{path / UUVS_DIR / uuv_id}: no such UUV in the session (it holds {', '.join(ids)})"
        )
    folder = path / UUVS_DIR / uuv_id
    return UuvFiles(uuv_id, folder, folder / UUV_TOML)


@dataclass
class Session:
    path: Path
    calibration: Calibration
    telemetry: Telemetry
    track: dict[str, np.ndarray] | None = None  # t, u, v (NaN where the UUV was not seen)
    frames: dict[str, np.ndarray] | None = None  # frame, t
    video_path: Path | None = None
    truth: dict[str, np.ndarray] | None = None  # t, lat, lon, depth_m
    warnings: list[str] = field(default_factory=list)
    uav_sysid: int | None = None
    uuv_id: str = PRIMARY_UUV  # whose depth, track, truth and [tracker] these are (see uuv_ids)

    def open_video(self, grey: bool = False) -> Video:
        """The session's video: frames numbered by ``video_frames.csv``, each checked against the calibration's
        image size; ``grey``: luma only (see :func:`groundstation.video.file.open_video`)."""
        cam = self.calibration.camera
        return open_video(
            self.video_path,
            expected_size=(cam.width, cam.height),
            indices=self.frames["frame"].astype(int),
            grey=grey,
        )


def _number(text: str, where: str, col: str, allow_empty: bool) -> float:
    text = text.strip()
    if text == "" and allow_empty:
        return math.nan
    try:
        value = float(text)
    except ValueError:
        raise SessionError(f"{where}: {col} = {text!r}: not a number") from None
    if not math.isfinite(value) and not allow_empty:
        raise SessionError(f"{where}: {col} = {text!r}: must be finite")
    return value


def read_table(
    path: Path,
    columns: tuple[str, ...],
    allow_empty: tuple[str, ...] = (),
    optional: tuple[str, ...] = (),
    text: tuple[str, ...] = (),
) -> dict[str, np.ndarray]:
    """A CSV with at least ``columns`` in its header, as float arrays; checks times increase.

    ``optional`` columns are read when the header has them; ``text`` columns are kept as
    non-empty strings (object arrays); ``allow_empty`` columns may be empty (NaN, or "" for text).
    """
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            header = reader.fieldnames or []
            missing = [c for c in columns if c not in header]
            if missing:
                raise SessionError(f"{path}: header {header!r} lacks {', '.join(missing)}")
            wanted = [*columns, *(c for c in optional if c in header)]
            cols: dict[str, list] = {c: [] for c in wanted}
            for row in reader:
                where = f"{path}:{reader.line_num}"
                for c in wanted:
                    if row[c] is None:
                        raise SessionError(f"{where}: row too short, no {c}")
                    if c in text:
                        if not row[c].strip() and c not in allow_empty:
                            raise SessionError(f"{where}: {c} = {row[c]!r}: empty")
                        cols[c].append(row[c].strip())
                    else:
                        cols[c].append(_number(row[c], where, c, c in allow_empty))
    except (OSError, UnicodeDecodeError) as e:
        raise SessionError(f"{path}: cannot read: {e}") from None
    out = {c: np.array(v, dtype=object if c in text else float) for c, v in cols.items()}
    t = out.get("t")
    if t is not None and len(t) > 1 and not np.all(np.diff(t) > 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise SessionError(f"{path}: t = {t[i + 1]!r} on data row {i + 2} does not increase")
    return out


def _read_depth(path: Path, tel: Telemetry, warnings: list[str]) -> int:
    """Feed depth.jsonl into ``tel`` (:func:`~groundstation.session.depth.read_depth`, strict): ``t`` (the
    UUV's stamp), ``t_recv`` (its arrival) when recorded, and the ``source``, ``sigma_m`` and ``vspeed_mps`` a
    recording wrote (the source "session" where none is named)."""
    count = refused = 0
    for r in read_depth(path, warnings):
        if tel.add_depth(
            r.t,
            r.depth_m,
            r.t_recv,
            sigma_m=r.sigma_m,
            source=r.source if r.source in SOURCE_WORDS else "session",
            vspeed_mps=r.vspeed_mps,
        ):
            count += 1
        else:
            refused += 1
    if refused:
        warnings.append(
            f"{path}: {refused} depth samples out of order once aligned to the station clock, skipped"
        )
    if count == 0:
        raise SessionError(f"{path}: no depth samples")
    return count


def _read_tlog(
    path: Path, timing: Timing, source: str, warnings: list[str], read: dict | None = None
) -> tuple[Telemetry, int]:
    """The UAV's messages ingested into a new :class:`~localizer.telemetry.Telemetry` with ``timing`` (the whole
    recording: two-sided heights), and the UAV's system id (:func:`~groundstation.mavlink.ingest.uav_system`).
    ``read``: the telemetry and the warnings the log made, kept there by the first call; the others with the same
    ``timing`` and ``source`` start from a copy of that telemetry (:func:`load_sessions`)."""
    if read is not None and path in read:
        kept, sysid, kept_warnings, kept_source = read[path]
        if kept.timing == timing and kept_source == source:
            warnings.extend(kept_warnings)
            return copy.deepcopy(kept, {id(kept.timing): timing}), sysid
    tel = Telemetry(timing)
    # the whole recording: each frame's height uses the GNSS altitudes after it too
    tel.height_two_sided = True
    mine: list[str] = []  # the warnings of this log
    sysid = _ingest_tlog(path, tel, source, mine)
    warnings.extend(mine)
    if read is not None and path not in read:
        read[path] = copy.deepcopy(tel, {id(timing): timing}), sysid, mine, source
    return tel, sysid


def _ingest_tlog(path: Path, tel: Telemetry, source: str, warnings: list[str]) -> int:
    """Ingest the UAV's messages into ``tel``; returns the UAV's system id."""
    msgs = [m for _, m in read_tlog(path, warnings)]
    sysid = uav_system(msgs)
    if sysid is None:
        raise SessionError(
            f"{path}: no ATTITUDE message nor any other from an autopilot (is this the UAV's telemetry?)"
        )
    others = 0
    counts: dict[str, int] = {}
    for m in msgs:
        if m.get_srcSystem() != sysid:
            others += 1
            continue
        if ingest(tel, m, m._timestamp):
            counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
    if others:
        warnings.append(
            f"{path}: {others} messages from systems other than the UAV (sysid {sysid}) ignored"
        )
    needed = ["ATTITUDE", "GLOBAL_POSITION_INT"]
    if source in _NEEDED_FOR_SOURCE:
        needed.append(_NEEDED_FOR_SOURCE[source])
    for kind in needed:
        if not counts.get(kind):
            raise SessionError(
                f"{path}: no usable {kind} message (mount.attitude_source = {source!r})"
            )
    for name, series in (("ATTITUDE", tel.attitude), ("GLOBAL_POSITION_INT", tel.position)):
        if series.rejected:
            warnings.append(
                f"{path}: {series.rejected} {name} samples out of order or non-finite, skipped"
            )
    return sysid


def clock_summary(tel: Telemetry) -> str:
    """One line on how the session's clocks were aligned."""
    parts = [f"UAV link delay {tel.uav_latency_s * 1000:.0f} ms ({tel.latency_source})"]
    gnss = tel.station_minus_gnss_s
    parts.append("no GNSS time (SYSTEM_TIME)" if gnss is None else f"station − GNSS {gnss:+.3f} s")
    if tel.uav_clock.segments:
        parts.append(f"{tel.uav_clock.segments} autopilot reboot(s)")
    uuv = tel.uuv_clock_minus_station_s
    if uuv is not None:
        parts.append(f"UUV clock − station {uuv:+.3f} s, depth aligned by {tel.depth_aligned_by}")
    return "clocks: " + ", ".join(parts)


def _read_toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise SessionError(f"{path}: missing") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise SessionError(f"{path}: malformed TOML: {e}") from None


def _calibration(meta: dict, toml_path: Path, uuv: UuvFiles) -> Calibration:
    """session.toml's calibration; for a UUV other than the first, with the ``[tracker]`` table of its ``uuv.toml``
    (none when it has no such file)."""
    source = str(toml_path)
    if uuv.tracker_toml != toml_path:
        tracker = (
            _read_toml(uuv.tracker_toml).get("tracker", {}) if uuv.tracker_toml.is_file() else {}
        )
        meta, source = {**meta, "tracker": tracker}, f"{toml_path} with {uuv.tracker_toml}"
    try:
        return Calibration.from_dict(meta, source=source)
    except ConfigError as e:
        raise SessionError(str(e)) from None


def load_sessions(path, uuvs: list[str]) -> list[Session]:
    """:func:`load_session` of each of ``uuvs``, the UAV's telemetry log parsed and ingested once for all (each
    UUV's :class:`~localizer.telemetry.Telemetry` a copy: the heights from size add to one UUV's alone)."""
    read: dict = {}
    return [load_session(path, uuv, read) for uuv in uuvs]


def video_file(path) -> Path | None:
    """The session directory ``path``'s video (the first ``video.*`` file by name), or None."""
    return next(iter(sorted(p for p in Path(path).glob("video.*") if p.is_file())), None)


def load_session(path, uuv: str = PRIMARY_UUV, read: dict | None = None) -> Session:
    """Read and validate a session directory, as the records of its UUV ``uuv`` (see :func:`uuv_ids`); ``read``:
    see :func:`load_sessions`."""
    path = Path(path)
    if not path.is_dir():
        raise SessionError(f"{path}: not a session directory")
    toml_path = path / "session.toml"
    meta = _read_toml(toml_path)
    version = meta.get("version")
    if version != SUPPORTED_VERSION:
        raise SessionError(
            f"{toml_path}: version = {version!r}: this skyfix reads version {SUPPORTED_VERSION}"
        )
    files = uuv_files(path, uuv)
    cal = _calibration(meta, toml_path, files)

    warnings: list[str] = list(cal.warnings)
    tel, sysid = _read_tlog(
        path / "uav.tlog", cal.timing, cal.mount.attitude_source, warnings, read
    )
    if not files.depth.is_file():
        raise SessionError(f"{files.depth}: missing (the UUV's depth is required)")
    _read_depth(files.depth, tel, warnings)
    warnings.extend(f"{path}: {notice}" for notice in tel.notices)
    tel.notices.clear()

    session = Session(
        path=path,
        calibration=cal,
        telemetry=tel,
        warnings=warnings,
        uav_sysid=sysid,
        uuv_id=files.id,
    )
    if files.track.is_file():
        session.track = read_table(files.track, ("t", "u", "v"), allow_empty=("u", "v"))
    if files.truth.is_file():
        session.truth = read_table(files.truth, ("t", "lat", "lon", "depth_m"))
    if (video := video_file(path)) is not None:
        session.video_path = video
        if not (path / "video_frames.csv").is_file():
            raise SessionError(f"{path / 'video_frames.csv'}: missing (required with {video.name})")
        session.frames = read_table(path / "video_frames.csv", ("frame", "t"))
        _restamp_unsettled(session)
    return session


def _restamp_unsettled(session: Session) -> None:
    """A live run with ``--video-latency-ms auto`` stamped its frames with no latency until its estimate
    settled (``[timing] video_latency_from_t``): those frames are moved back by the estimate it recorded."""
    timing, t = session.calibration.timing, session.frames["t"]
    if (
        timing.video_latency_source != "motion"
        or timing.video_latency_from_t is None
        or timing.video_latency_s is None
    ):
        return
    early = t < timing.video_latency_from_t
    if early.any():
        t[early] -= timing.video_latency_s
        session.warnings.append(
            f"{session.path / 'video_frames.csv'}: {int(early.sum())} frames stamped before the live run's video "
            f"latency had settled moved back by the {timing.video_latency_s * 1000:.1f} ms it settled at "
            "([timing] video_latency_s)"
        )
