"""Warnings about bad input: one line each, thinned out so a flood of garbage cannot drown the log."""

from __future__ import annotations

from collections import Counter


class Throttle:
    """Counts each kind of problem; says whether this occurrence is worth a log line.

    The first ``first`` occurrences of a kind are logged, then every ``every``-th, so
    each distinct problem is named while a flood of the same one stays a trickle.
    """

    def __init__(self, first: int = 5, every: int = 100):
        self.first, self.every = first, every
        self.counts: Counter[str] = Counter()

    def __call__(self, kind: str) -> int | None:
        """The occurrence number of ``kind`` if it should be logged, else None."""
        self.counts[kind] += 1
        n = self.counts[kind]
        return n if n <= self.first or n % self.every == 0 else None
