"""Progress of long offline runs (tracking a video, rendering a scenario) on stderr, with an ETA.

A tqdm bar: redrawn at most twice a second on a terminal and every 30 s into a log
file or pipe (so a CI log gets a few lines, not thousands); ``enabled=False``
(``--quiet``) prints nothing.
"""

from __future__ import annotations

import sys

from tqdm import tqdm

FORMAT = "{desc}: {percentage:3.0f}% {n_fmt}/{total_fmt} frames [{elapsed} elapsed, ETA {remaining}, {rate_fmt}]"


def progress(total: int, desc: str, enabled: bool = True) -> tqdm:
    """A progress bar over ``total`` frames; ``update(n)`` as they are done, ``close()`` at the end."""
    tty = sys.stderr.isatty()
    return tqdm(
        total=total,
        desc=desc,
        disable=not enabled,
        file=sys.stderr,
        unit=" frames",
        mininterval=0.5 if tty else 30.0,
        bar_format=FORMAT,
        dynamic_ncols=True,
    )
