"""Why GPS_INPUT says "no fix": one word per reason and the plain words the operator reads.

The sink (:mod:`.gps_input`) names the reason of each no-fix message it sends; the status carries the
word (``gps_input.no_fix_reason``) and its plain words (``no_fix_why``), and the web page's header shows
the words. The reasons:

- a fix status other than ``ok`` (:data:`localizer.status.STATUSES`): the newest frame's, when it is why
  nothing valid is left (the tracker lost the UUV, awaits a target, the telemetry is stale, ...);
- ``gate_<reason>`` (:data:`localizer.fix_gate.REASONS`): the newest fix was ok but the safety gates held
  it back (a target being confirmed, a fix off the UUV's track, ...);
- ``no_frames``: no frame has been tracked yet; ``no_new_fix``: the last valid fix aged out and no frame
  came after it (the video stopped, or the tracker stalled); ``stopped``: skyfix stopped (its last message).
"""

from __future__ import annotations

from localizer.fix import Fix
from localizer.fix_gate import REASONS
from localizer.status import STATUSES

#: a fix status → the operator's words for it
_STATUS_WORDS = {
    "lost": "tracker lost the UUV",
    "no_track": "no pixel for the frame",
    "not_initialized": "tracker not started",
    "awaiting_target": "awaiting a target",
    "released": "target released",
    "before_init": "before the first box",
    "no_video": "frame not decoded",
    "buffered": "frame time unknown",
    "bad_pixel": "pixel outside the lens model",
    "no_water": "ray misses the water",
    "below_surface": "camera at or below the water",
    "bad_time": "frame time not a number",
    "latency_unsettled": "video latency not settled",
    "no_attitude": "no attitude telemetry",
    "stale_attitude": "attitude telemetry stale",
    "no_position": "no UAV position",
    "stale_position": "UAV position stale",
    "no_gimbal": "no gimbal attitude",
    "stale_gimbal": "gimbal attitude stale",
    "no_depth": "no UUV depth",
    "stale_depth": "UUV depth stale",
    "same_vehicle": "two trackers on one vehicle",
    "disagree": "drones disagree",
}
#: a safety gate's refusal → the operator's words for it
_GATE_WORDS = {
    "h_acc": "accuracy too poor for the autopilot",
    "age": "fix too old when offered",
    "out_of_order": "fix out of order",
    "clock": "a clock stepped: confirming again",
    "prediction": "fix outside the predicted window",
    "innovation": "fix off the UUV's track",
    "diverged": "fixes left the UUV's track",
    "reach": "fix beyond the UUV's reach",
    "unconfirmed": "confirming the target",
    "exchanged": "may be the other UUV: not told apart yet",
}
#: every reason word → its plain words (a status or refusal without short words here: its own description)
NO_FIX_WHY: dict[str, str] = {
    **{k: _STATUS_WORDS.get(k, text) for k, text in STATUSES.items() if k != "ok"},
    **{f"gate_{k}": _GATE_WORDS.get(k, f"the safety gates refused it ({k})") for k in REASONS},
    "no_frames": "no frame tracked yet",
    "no_new_fix": "no new fix: video stopped or stalled",
    "stopped": "skyfix stopped",
}


def no_fix_reason(latest: Fix | None, refusal: str | None) -> str:
    """The reason word of a no-fix message: ``latest`` is the newest frame's fix (None: no frame yet), ``refusal``
    the gates' word for it when it was ok (None: taken, so it can only have aged out since)."""
    if latest is None:
        return "no_frames"
    if not latest.ok:
        return latest.status
    return "no_new_fix" if refusal is None else f"gate_{refusal}"
