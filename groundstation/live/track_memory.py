"""Each UUV's last trusted track kept on disk, so that a restart comes back careful.

The safety gates (:mod:`localizer.fix_gate`) judge a new target against the last trusted track of the UUV;
a fresh process has none, and would take anything consistent for a second. :class:`TrackMemory` writes
the gate's track (:meth:`~localizer.fix_gate.FixGate.memory`: position, velocity, covariances, the fixes'
shared error, its age) to ``<state_dir>/track-<uuv id>.json`` every :data:`WRITE_EVERY_S` while it
changes, and once more at the end, atomically (a temporary file in the same folder, flushed and synced,
then renamed over the old one: a crash leaves the old track or the new, never half of one). At the start
(:func:`read_track`) a kept track younger than ``--track-max-age-s`` is handed to the new gate
(:meth:`~localizer.fix_gate.FixGate.remember`): the first target must then be within reach of it, or the
operator confirms it.

Age: the track's age when written plus the time since, on the kernel's boot clock (``CLOCK_BOOTTIME``,
which counts suspended time and never steps) when the machine has not rebooted since (same
``/proc/sys/kernel/random/boot_id``), else on the station clock; an age below zero (the station clock
went back across a reboot) is taken as zero: the reach is then the smallest, never wider.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import os
import tempfile
import time
from pathlib import Path

from localizer.fix_gate import FixGate

log = logging.getLogger("skyfix.track_memory")

#: The kept track is written at most this often (s).
WRITE_EVERY_S = 1.0
#: A kept track older than this (s) is not read (``--track-max-age-s``'s default).
MAX_AGE_S = 300.0
BOOT_ID = Path("/proc/sys/kernel/random/boot_id")
KEYS = ("t", "lat", "lon", "vn_mps", "ve_mps", "P", "C", "common", "age_s")


def track_path(state_dir: str | Path, uuv_id: str) -> Path:
    return Path(state_dir) / f"track-{uuv_id}.json"


def _boot() -> tuple[str | None, float]:
    """This boot's id (None where the kernel gives none) and the boot clock (s)."""
    try:
        boot_id = BOOT_ID.read_text().strip()
    except OSError:
        boot_id = None
    return boot_id, time.clock_gettime(time.CLOCK_BOOTTIME)


def write_track(path: Path, memory: dict) -> None:
    """``memory`` (:meth:`FixGate.memory`) with when it was written, atomically; OSError when it cannot be."""
    boot_id, boot_s = _boot()
    text = json.dumps(
        {**memory, "written_unix": time.time(), "boot_id": boot_id, "boot_s": boot_s},
        allow_nan=False,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def read_track(path: Path, max_age_s: float) -> tuple[dict, float] | None:
    """The kept track and its age now (s), or None: no file, or older than ``max_age_s`` (logged). A file that does
    not read as a kept track is logged and not used."""
    try:
        kept = json.loads(path.read_text())
        if not isinstance(kept, dict) or any(k not in kept for k in KEYS):
            raise ValueError(f"expected the keys {', '.join(KEYS)}")
        boot_id, boot_s = _boot()
        since = (
            boot_s - float(kept["boot_s"])
            if boot_id is not None and kept.get("boot_id") == boot_id
            else time.time() - float(kept["written_unix"])
        )
        age_s = max(0.0, float(kept["age_s"]) + since)
        if not math.isfinite(age_s):
            raise ValueError(f"age {age_s}")
    except FileNotFoundError:
        return None
    except (OSError, ValueError, TypeError, KeyError) as e:
        log.warning(
            "%s: not a kept track (%s): the gates start without the UUV's last track", path, e
        )
        return None
    if age_s > max_age_s:
        log.info(
            "%s: the UUV's last track is %.0f s old (over --track-max-age-s %g): not used",
            path,
            age_s,
            max_age_s,
        )
        return None
    return kept, age_s


def remember(gate: FixGate, path: Path, max_age_s: float) -> dict | None:
    """Hand the kept track at ``path`` to ``gate`` (a new one): what was read (for the status), or None."""
    found = read_track(path, max_age_s)
    if found is None:
        return None
    kept, age_s = found
    gate.remember(kept, time.time() - age_s)
    log.info(
        "%s: the UUV's last trusted track, %.1f s old: a target further than it can have gone is not valid "
        "until the operator confirms it",
        path,
        age_s,
    )
    return {"age_s": round(age_s, 3), "lat": kept["lat"], "lon": kept["lon"]}


class TrackMemory:
    """Worker keeping ``gate``'s track at ``path`` (see the module doc); ``read``: what the start read (status)."""

    def __init__(self, gate: FixGate, path: Path, read: dict | None = None):
        self.gate = gate
        self.path = path
        self.read = read
        self.written = 0
        self.failure: str | None = None
        self._last_t: float | None = None

    async def run(self) -> None:
        try:
            while True:
                self.write()
                await asyncio.sleep(WRITE_EVERY_S)
        finally:
            self.write()

    def write(self) -> None:
        """The gate's track, when it changed since the last write."""
        memory = self.gate.memory(time.time())
        if memory is None or memory["t"] == self._last_t:
            return
        try:
            write_track(self.path, memory)
        except OSError as e:
            if self.failure is None:
                log.warning("%s: cannot keep the UUV's track: %s", self.path, e)
            self.failure = str(e)
            return
        self._last_t, self.failure = memory["t"], None
        self.written += 1

    def status(self) -> dict:
        return {
            "path": str(self.path),
            "written": self.written,
            "read": self.read,
            "failure": self.failure,
        }
