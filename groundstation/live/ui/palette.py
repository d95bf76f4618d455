"""Each UUV's colour on the web page (its box and label on the video, its track on the map, its rows): a fixed
palette in the order of the run's UUVs (``[[uuv]]`` tables), repeated after the last. The first is the colour the
page has always drawn the one UUV's track in; all are dark enough for white text and visible on water and on
the map's white."""

from __future__ import annotations

PALETTE = (
    "#b00000",
    "#6a1b9a",
    "#d35400",
    "#00796b",
    "#c2185b",
    "#5d4037",
)  # red, purple, orange, teal, pink, brown


def colour(i: int) -> str:
    """The ``i``-th UUV's colour (0 the first)."""
    return PALETTE[i % len(PALETTE)]
