"""Warnings about bad input: one line each, thinned out so a flood of garbage cannot drown the log."""

from __future__ import annotations

import re
from collections import Counter

#: Values in a message's text: quoted strings, hex and decimal numbers (a CRC, a count, a byte)
_VALUES = re.compile(r"'[^']*'|\"[^\"]*\"|\b0x[0-9a-fA-F]+\b|[-+]?\b\d+(\.\d+)?([eE][-+]?\d+)?\b")
KIND_CHARS = 80


def kind_of(text: str) -> str:
    """The kind of problem a free text (FFmpeg's, pymavlink's) names: its words without the values in it.

    ``invalid MAVLink CRC in msgID 30 0x1e85 should be 0x5c52`` → ``invalid MAVLink CRC in msgID # # should be #``.
    """
    return _VALUES.sub("#", text)[:KIND_CHARS]


class Throttle:
    """Counts each kind of problem; says whether this occurrence is worth a log line.

    The first ``first`` occurrences of a kind are logged, then every ``every``-th, so
    each distinct problem is named while a flood of the same one stays a trickle.
    The caller names the kind (a fixed word, or :func:`kind_of` a free text); the log
    line itself carries the offending value. At most ``max_kinds`` are told apart (the
    rest count as one): memory stays bounded whatever the input.
    """

    def __init__(self, first: int = 5, every: int = 100, max_kinds: int = 64):
        self.first, self.every, self.max_kinds = first, every, max_kinds
        self.counts: Counter[str] = Counter()

    def __call__(self, kind: str) -> int | None:
        """The occurrence number of ``kind`` if it should be logged, else None."""
        key = kind[:KIND_CHARS]
        if key not in self.counts and len(self.counts) >= self.max_kinds:
            key = "(other)"
        self.counts[key] += 1
        n = self.counts[key]
        return n if n <= self.first or n % self.every == 0 else None
