"""Warnings about bad input: one line each, thinned out so a flood of garbage cannot drown the log."""

from __future__ import annotations

import re
from collections import Counter

_NUMBERS = re.compile(r"\b(0x[0-9a-fA-F]+|\d+(\.\d+)?)\b")


class Throttle:
    """Counts each kind of problem; says whether this occurrence is worth a log line.

    The first ``first`` occurrences of a kind are logged, then every ``every``-th, so
    each distinct problem is named while a flood of the same one stays a trickle.
    A kind is its text with the numbers taken out (a CRC or a count does not make
    a new kind), and at most ``max_kinds`` are told apart: memory stays bounded
    whatever the input.
    """

    def __init__(self, first: int = 5, every: int = 100, max_kinds: int = 64):
        self.first, self.every, self.max_kinds = first, every, max_kinds
        self.counts: Counter[str] = Counter()

    def __call__(self, kind: str) -> int | None:
        """The occurrence number of ``kind`` if it should be logged, else None."""
        key = _NUMBERS.sub("#", kind)
        if key not in self.counts and len(self.counts) >= self.max_kinds:
            key = "(other)"
        self.counts[key] += 1
        n = self.counts[key]
        return n if n <= self.first or n % self.every == 0 else None
