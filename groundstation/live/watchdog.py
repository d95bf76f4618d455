"""Saying what is wrong, early and again: a worker that reads the service's status once a second.

Per input, one log line when it is silent or failing — within :data:`FIRST_S` of the
start, then again with back-off (10, 20, 40, 60 s …) while it lasts, and once
when it is back:

- the UAV's MAVLink: nothing received yet, silent, or needed messages missing;
- the UUV's depth: nothing yet on its Zenoh key or MAVLink link, no depth from it, none for a while, or
  only ArduSub's EKF depth (its depth sensor's parameters or message not received);
- the video: no frame decoded yet (with FFmpeg's reason), or none for a while;
- Zenoh: no peer or router connected;
- ``--record``: the recording stopped (a full disk).

It reads the inputs' sections of the status as their models (:class:`~groundstation.messages.InputsStatus`),
field by field. The current problems are in the status (``problems``, per input). Every
:data:`SUMMARY_S` a one-line summary: frames per second, the share of ``ok``
fixes, the last fix and every input's age. With ``require_s`` (``--require-inputs``),
an input never heard from by then stops the service: :class:`InputMissing`.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable

from pydantic import ValidationError

from groundstation.messages import InputsStatus
from localizer.fix import Fix

log = logging.getLogger("skyfix.inputs")

FIRST_S = 5.0  # first report this long after the start
REPEAT_S = (10.0, 20.0, 40.0, 60.0)  # then after these intervals, the last one repeated
SUMMARY_S = 10.0
SILENT_S = 3.0  # an input whose newest sample is older than this is silent
REQUIRE_S = 10.0  # --require-inputs: every input must have delivered something by then


class InputMissing(RuntimeError):
    """An input required by ``--require-inputs`` was never heard from; the message is one line."""


def never_heard(inputs: InputsStatus) -> list[str]:
    """The inputs that have not delivered anything yet: ``uav``, ``depth``, ``video``."""
    return [
        name
        for name, silent in (
            ("uav", inputs.uav.received == 0),
            ("depth", inputs.depth.received == 0),
            ("video", inputs.video is not None and inputs.video.frames == 0),
        )
        if silent
    ]


def problems(
    inputs: InputsStatus, needed: tuple[str, ...], zenoh_peers: int | None
) -> dict[str, str]:
    """What is wrong with each input, from the inputs' status (empty when all is well)."""
    out = {}
    uav = inputs.uav
    ages = uav.age_s
    if uav.received == 0:
        out["uav"] = f"UAV MAVLink: nothing received on {uav.url}"
    elif min(ages.values()) > SILENT_S:
        out["uav"] = f"UAV MAVLink: silent for {min(ages.values()):.0f} s on {uav.url}"
    else:
        missing = [k for k in needed if ages.get(k, math.inf) > SILENT_S]
        if missing:
            out["uav"] = (
                f"UAV MAVLink: no {', '.join(missing)} (receiving {', '.join(sorted(ages))})"
            )
    depth = inputs.depth
    where = f"Zenoh key {depth.key}" if depth.key else depth.url
    if depth.received == 0:
        out["depth"] = f"depth: nothing received on {where}"
    elif depth.age_s is None:
        missing = depth.ardusub.params.missing if depth.ardusub else None
        why = f" (ArduSub has not answered {', '.join(missing)} yet)" if missing else ""
        out["depth"] = f"depth: {depth.received} messages on {where}, no depth from them{why}"
    elif depth.age_s > SILENT_S:
        out["depth"] = f"depth: none for {depth.age_s:.0f} s on {where}"
    elif depth.source == "ardusub_ekf":
        missing = ", ".join(depth.ardusub.params.missing) or "its depth sensor's message"
        out["depth"] = (
            f"depth: ArduSub's EKF only, unchecked: {missing} not received yet on {where}"
        )
    video = inputs.video
    if video is not None:
        why = f": {video.error}" if video.error else ""
        if video.frames == 0:
            out["video"] = f"video: no frame from {video.url}{why}"
        elif video.age_s is not None and video.age_s > SILENT_S:
            out["video"] = f"video: no frame for {video.age_s:.0f} s from {video.url}{why}"
    if zenoh_peers == 0:
        out["zenoh"] = "Zenoh: no peer or router connected"
    if inputs.record is not None and inputs.record.error:
        out["record"] = f"record: stopped: {inputs.record.error}"
    return out


class Watchdog:
    """Worker and sink (``on_fix``): the log lines above, ``problems`` for the status, the summary."""

    def __init__(
        self,
        status: Callable[[float], dict],
        needed: tuple[str, ...],
        zenoh_peers: Callable[[], int] | None = None,
        require_s: float | None = None,
    ):
        self.status = status
        self.needed = needed
        self.zenoh_peers = zenoh_peers
        self.require_s = require_s
        self.problems: dict[str, str] = {}
        self._next_report: dict[
            str, tuple[float, int]
        ] = {}  # input → (when to log again, repeats so far)
        self._fixes = 0
        self._ok = 0
        self._last_ok: Fix | None = None

    def on_fix(self, fix: Fix, info) -> None:
        self._fixes += 1
        if fix.ok:
            self._ok += 1
            self._last_ok = fix

    async def run(self) -> None:
        t0 = time.time()
        next_summary = t0 + SUMMARY_S
        while True:
            await asyncio.sleep(1.0)
            now = time.time()
            try:
                status = InputsStatus.model_validate(self.status(now))
            except (
                ValidationError
            ) as e:  # a bug, not the field's: the status sink names the field; judge the next
                log.debug("inputs' status does not fit its model: %s", e)
                continue
            peers = self.zenoh_peers() if self.zenoh_peers is not None else None
            self.problems = problems(status, self.needed, peers)
            self._report(now, t0)
            if self.require_s is not None and now - t0 >= self.require_s:
                never = never_heard(status)
                if never:
                    raise InputMissing(
                        "; ".join(self.problems[k] for k in never)
                        + f" within {self.require_s:g} s (--require-inputs)"
                    )
                self.require_s = None
            if now >= next_summary:
                log.info("%s", self.summary(now, status))
                self._fixes = self._ok = 0
                next_summary = now + SUMMARY_S

    def _report(self, now: float, t0: float) -> None:
        for key, text in self.problems.items():
            when, repeats = self._next_report.get(key, (t0 + FIRST_S, 0))
            if now >= when:
                log.warning("%s", text)
                self._next_report[key] = (
                    now + REPEAT_S[min(repeats, len(REPEAT_S) - 1)],
                    repeats + 1,
                )
        for key in [k for k in self._next_report if k not in self.problems]:
            if self._next_report.pop(key)[1]:
                log.info("%s: back", key)

    def summary(self, now: float, status: InputsStatus) -> str:
        """One line: frames per second, ok share, the last fix and the inputs' ages, over the last interval."""
        ok = f"{100.0 * self._ok / self._fixes:.0f}% ok" if self._fixes else "no frames"
        fix = self._last_ok
        last = (
            "no fix yet"
            if fix is None
            else f"last fix {fix.lat:.7f}, {fix.lon:.7f} ±{fix.h_acc_m:.2f} m {now - fix.t_unix:.1f} s ago"
        )
        ages = status.uav.age_s
        parts = [
            f"{self._fixes / SUMMARY_S:.1f} fps",
            ok,
            last,
            f"UAV {_age(min(ages.values()) if ages else None)}",
            f"depth {_age(status.depth.age_s)}",
        ]
        if status.video is not None:
            parts.append(f"video {_age(status.video.age_s)}")
        return "; ".join(parts)


def _age(age_s: float | None) -> str:
    return "never" if age_s is None else f"{age_s:.2f} s"
