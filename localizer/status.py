"""Every status word a fix can carry: ``ok``, or why there is no position.

The one list of them: the fix message's JSON Schema enumerates :data:`STATUSES`,
``positions.csv`` and the exports carry the same words, and a test checks that the
code produces no other. A new word is one entry here (then regenerate the schemas:
``python -m groundstation.contracts``).
"""

from __future__ import annotations

from typing import Literal

#: word → what it means (for the docs' status words page, the schema and the reports)
STATUSES: dict[str, str] = {
    "ok": "a valid fix",
    # tracking
    "lost": "the tracker lost the UUV (weak match, or it left the predicted window)",
    "no_track": "no pixel for this frame (track.csv row without u, v)",
    "not_initialized": "the tracker has not been given the UUV yet",
    "awaiting_target": "live: waiting for the operator to designate the UUV",
    "released": "live: the operator released the target; no tracking until a new one",
    "before_init": "offline: a frame before the one init_bbox belongs to",
    "no_video": "offline: the frame is listed in video_frames.csv but could not be decoded",
    "buffered": "live, older recordings: the video reader could not tell this frame's exposure time",
    # geometry
    "bad_pixel": "the pixel is outside the image or the lens model",
    "no_water": "the ray through the pixel never reaches the water",
    "below_surface": "the camera is at or below the water surface (check [water])",
    "bad_time": "the frame's time is not a finite number",
    "latency_unsettled": "live, --video-latency-ms auto: the video's latency is not yet settled from the image's "
    "motion, so the frame's exposure time is not known",
    # telemetry ([timing] sets how far apart and how old samples may be)
    "no_attitude": "no ATTITUDE sample at or before the frame",
    "stale_attitude": "the ATTITUDE samples around the frame are too far apart or too old",
    "no_position": "no GLOBAL_POSITION_INT sample at or before the frame",
    "stale_position": "the GLOBAL_POSITION_INT samples around the frame are too far apart or too old",
    "no_gimbal": "no gimbal attitude sample at or before the frame",
    "stale_gimbal": "the gimbal attitude samples around the frame are too far apart or too old",
    "no_depth": "no UUV depth sample at or before the frame",
    "stale_depth": "the UUV depth samples around the frame are too far apart or too old",
    # several UUVs in one video, several drones over one UUV (skyfix fuse)
    "same_vehicle": "live, several UUVs: this UUV's tracker box coincides with another UUV's (both trackers on one "
    "vehicle, or the two right over each other): no fix for either until they part or one is selected "
    "again",
    "disagree": "skyfix fuse: the drones' fixes disagree beyond their sigmas and none of them can be told right",
    "off_track": "skyfix fuse: the fused position lies beyond where the UUV can be by the fused fixes' own track",
    # offline
    "refused": "offline, positions_smoothed.csv: the safety gates refused this frame's fix (off the UUV's track, or a "
    "target never confirmed) and the fixes around it are too far apart to bridge",
}

Status = Literal[tuple(STATUSES)]


def runs(status) -> list[tuple[int, int, str]]:
    """Consecutive frames with the same status: ``(first, last + 1, word)`` in order."""
    out: list[tuple[int, int, str]] = []
    start = 0
    for i in range(1, len(status) + 1):
        if i == len(status) or status[i] != status[start]:
            out.append((start, i, str(status[start])))
            start = i
    return out
