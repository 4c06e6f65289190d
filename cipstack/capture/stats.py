"""Bounded per-connection statistics: a log-bucket histogram for quantiles, a reservoir for plots.

A multi-gigabyte capture holds millions of intervals per connection; keeping them all would make
memory grow with the file. The histogram keeps one counter per 0.1 % wide bucket (at most about 23,000
buckets between 1 us and 10,000 s), so a quantile is exact to within 0.1 % of its value whatever
the number of samples; the maximum, the count and the share within a tolerance are exact.
"""

from __future__ import annotations

import heapq
import math
import random
from dataclasses import dataclass, field

#: Relative width of a histogram bucket: quantiles are reported to within this fraction.
BUCKET_GROWTH = 1.001
_LOG_GROWTH = math.log(BUCKET_GROWTH)
#: Values below this (seconds) share bucket 0.
FLOOR = 1e-6


@dataclass
class LogHistogram:
    """Counts of positive values in logarithmic buckets; memory bounded by the value range."""

    counts: dict[int, int] = field(default_factory=dict)
    count: int = 0
    maximum: float = 0.0
    minimum: float = math.inf

    def add(self, value: float) -> None:
        index = 0 if value <= FLOOR else int(math.log(value / FLOOR) / _LOG_GROWTH) + 1
        counts = self.counts
        counts[index] = counts.get(index, 0) + 1
        self.count += 1
        if value > self.maximum:
            self.maximum = value
        if value < self.minimum:
            self.minimum = value

    def quantile(self, q: float) -> float | None:
        """The value below which a share ``q`` of the samples lie (bucket midpoint, clamped to min/max)."""
        if not self.count:
            return None
        rank = min(self.count - 1, int(q * self.count))
        seen = 0
        for index in sorted(self.counts):
            seen += self.counts[index]
            if seen > rank:
                value = FLOOR if index == 0 else FLOOR * BUCKET_GROWTH ** (index - 0.5)
                return min(max(value, self.minimum), self.maximum)
        return self.maximum  # pragma: no cover - the loop always reaches the rank


class Reservoir:
    """A uniform sample of at most ``size`` items from a stream of any length, deterministic for a
    given seed so two runs over one file plot the same points. Algorithm L (Li, 1994): once full,
    it draws how many items to skip, so most items cost a counter increment, not a random number."""

    def __init__(self, size: int = 5000, seed: int = 0) -> None:
        self.size = size
        self.items: list[tuple[float, float]] = []
        self.seen = 0
        self._random = random.Random(seed)
        self._weight = 1.0
        self._next = 0

    def _skip(self) -> None:
        draw = self._random.random
        self._weight *= math.exp(math.log(draw() or 1e-300) / self.size)
        self._next += int(math.log(draw() or 1e-300) / math.log1p(-self._weight)) + 1

    def add(self, item: tuple[float, float]) -> None:
        self.seen += 1
        if len(self.items) < self.size:
            self.items.append(item)
            if len(self.items) == self.size:
                self._next = self.seen
                self._skip()
            return
        if self.seen == self._next:
            self.items[self._random.randrange(self.size)] = item
            self._skip()

    def sorted(self) -> list[tuple[float, float]]:
        return sorted(self.items)


class Worst:
    """The ``size`` largest (value, time) pairs of a stream: the spikes a uniform sample may miss."""

    def __init__(self, size: int = 50) -> None:
        self.size = size
        self.heap: list[tuple[float, float]] = []
        #: A value must exceed this to enter (the smallest kept, once full): a cheap test for callers.
        self.floor = -math.inf

    def add(self, value: float, time: float) -> None:
        if len(self.heap) < self.size:
            heapq.heappush(self.heap, (value, time))
        elif value > self.heap[0][0]:
            heapq.heapreplace(self.heap, (value, time))
        if len(self.heap) == self.size:
            self.floor = self.heap[0][0]
