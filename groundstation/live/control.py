"""The operator's commands: in-process (:class:`Control`), and as Zenoh queryables through
:class:`groundstation.runtime.queries.ZenohControl`.

Commands, each a Zenoh queryable on ``<prefix>/<command>`` (``--control-prefix``,
default ``skyfix/cmd``) taking a JSON payload and answering JSON (encoding
``application/json``)::

    select   {"box": [x, y, w, h], "frame": 1234}    # or {"point": [u, v], "frame": 1234}; "frame" optional
             -> {"frame": 1234, "u": 331.2, "v": 190.8, "box": [..], "caught_up": 6, "latest_frame": 1240,
                 "target": {...}}
    release  (no payload)  -> {"latest_frame": 1240, "target": {...}}
    acquire  (no payload)  -> {"latest_frame": 1240, "target": {...}}   # await a target again (from the prior)
    confirm  (no payload)  -> {"confirmed": true, "why": "...", "target": {...}}   # the target tracked now is the UUV
    status   (no payload)  -> the service's status now, as published on the status key

``frame`` is the running frame number of the fixes (``"frame"`` in the fix JSON); it
must still be held (the last ``--select-history-s``); without it, the newest frame.
``latest_frame`` is the newest frame tracked when the command ran: every fix of a later
frame follows it (after a release, every later fix is ``released`` until a new selection;
frames tracked before it but not yet sent are ``released`` too). GPS_INPUT says no fix
from the first released fix on: until then (one frame) it may repeat the previous fix,
and without frames that fix expires after ``--fix-max-age-ms``. ``u``, ``v`` is the
selected frame's tracked pixel (the top face's centre), ``caught_up`` the held frames
tracked since it. A box is checked over the frames of its first ``STEADY_S`` (the held
frames after it, then the frames to come; :mod:`groundstation.live.pipeline`): the answer
waits for that verdict (a refusal is an error reply) and says where the target is then.
Pixels follow OpenCV (distorted image, u right, v down, top-left pixel centre (0, 0)).
``target`` is the tracking session's status: ``state`` (``awaiting_target``,
``tracking``, ``lost``, ``confirming``, ``released``), ``origin`` (``box``, ``click``,
``prior``), ``since_t``, the last frame's ``status``, ``u``, ``v``, ``box``,
``confidence``. A command that cannot be done (bad payload, frame no longer held, a
click on nothing) gets a Zenoh error reply ``{"error": "<one line>"}`` and changes nothing.
``confirm``: the operator's word that the target tracked now is the UUV, for the safety gates
(:meth:`localizer.fix_gate.FixGate.confirm`): after a restart, a selection or a loss, a target
out of reach of the UUV's last trusted track is never valid without it; with it, its fixes are
valid after a second of consistent fixes (``confirmed`` false, and why, while the gates track the
target already; refused without GPS_INPUT). It holds until the target is lost, released or
selected again. select, release, acquire and confirm act only on queries for their exact key (a
``skyfix/**`` query does not run them).

Late joiners: queryables on the fix key and the status key answer the latest fix
and status published there.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable

from groundstation.live.pipeline import Pipeline
from groundstation.runtime.queries import COMMANDS, ControlError, jsonable
from localizer.tracking.session import SelectionError

log = logging.getLogger("skyfix.control")


def _numbers(key: str, value, n: int) -> tuple[float, ...]:
    if (
        not isinstance(value, list)
        or len(value) != n
        or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
            for x in value
        )
    ):
        raise ControlError(f"select: {key} = {json.dumps(value)}: expected {n} finite numbers")
    return tuple(float(x) for x in value)


def parse_select(payload: bytes) -> dict:
    """``{"frame": int | None, "box": (x, y, w, h) | None, "point": (u, v) | None}`` of a select payload."""
    try:
        obj = json.loads(payload)
    except (ValueError, UnicodeDecodeError, RecursionError):
        raise ControlError(
            f'select: payload {payload[:80]!r}: expected JSON {{"box": [x, y, w, h]}} or '
            '{"point": [u, v]}, optionally with "frame"'
        ) from None
    if not isinstance(obj, dict):
        raise ControlError(f"select: payload {json.dumps(obj)[:80]}: expected a JSON object")
    unknown = sorted(set(obj) - {"frame", "box", "point"})
    if unknown:
        raise ControlError(f"select: unknown key {unknown[0]!r} (known: frame, box, point)")
    if ("box" in obj) == ("point" in obj):
        raise ControlError('select: give either "box": [x, y, w, h] or "point": [u, v]')
    frame = obj.get("frame")
    if frame is not None and (isinstance(frame, bool) or not isinstance(frame, int) or frame < 0):
        raise ControlError(f"select: frame = {json.dumps(frame)}: expected a frame number ≥ 0")
    box = _numbers("box", obj["box"], 4) if "box" in obj else None
    if box is not None and not (box[2] > 0 and box[3] > 0):
        raise ControlError(f"select: box = {json.dumps(obj['box'])}: width and height must be > 0")
    point = _numbers("point", obj["point"], 2) if "point" in obj else None
    return {"frame": frame, "box": box, "point": point}


class Control:
    """The commands in-process (for the Zenoh queryables and a web page); ``status(now)`` is the service's;
    ``confirm()`` the safety gates' (:meth:`localizer.fix_gate.FixGate.confirm`; None: no GPS_INPUT)."""

    def __init__(
        self,
        pipeline: Pipeline,
        status: Callable[[float], dict],
        confirm: Callable[[], dict] | None = None,
    ):
        self.pipeline = pipeline
        self._status = status
        self._confirm = confirm

    async def select(self, frame: int | None = None, box=None, point=None) -> dict:
        """Track the UUV in ``box`` (x, y, w, h) or at the click ``point`` (u, v) of frame ``frame`` (default newest)."""
        try:
            return jsonable(await self.pipeline.select(frame, box, point))
        except SelectionError as e:
            raise ControlError(f"select: {e}") from None

    async def release(self) -> dict:
        return jsonable(await self.pipeline.release())

    async def acquire(self) -> dict:
        return jsonable(await self.pipeline.acquire())

    def confirm(self) -> dict:
        """The target tracked now is the UUV: the safety gates take it without the reach test."""
        if self._confirm is None:
            raise ControlError(
                "confirm: this run sends no GPS_INPUT: there are no safety gates to confirm to"
            )
        done = self._confirm()
        log.info("the operator confirmed the target: %s", done["why"])
        return jsonable({**done, "target": self.pipeline.target})

    def status(self) -> dict:
        now = time.time()
        return jsonable({"t": now, **self._status(now)})

    async def handle(self, command: str, payload: bytes) -> dict:
        """Run a command with its JSON payload (see the module doc); raises :class:`ControlError`."""
        if command == "select":
            return await self.select(**parse_select(payload))
        if payload.strip() not in (b"", b"{}", b"null"):
            raise ControlError(f"{command}: payload {payload[:80]!r}: takes none")
        if command == "release":
            return await self.release()
        if command == "acquire":
            return await self.acquire()
        if command == "confirm":
            return self.confirm()
        if command == "status":
            return self.status()
        raise ControlError(f"unknown command {command!r} (known: {', '.join(COMMANDS)})")
