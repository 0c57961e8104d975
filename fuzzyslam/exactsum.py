"""Exactly rounded running sums."""

from __future__ import annotations

import math


class ExactSum:
    """Exactly rounded running sum of floats in O(1) memory (Shewchuk's partials, the
    algorithm of ``math.fsum``: J. R. Shewchuk, "Adaptive precision floating-point
    arithmetic", Discrete Comput. Geom. 18, 1997)."""

    def __init__(self) -> None:
        self.partials: list[float] = []
        self.n = 0

    def add(self, x: float) -> None:
        i = 0
        for y in self.partials:
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            lo = y - (hi - x)
            if lo:
                self.partials[i] = lo
                i += 1
            x = hi
        self.partials[i:] = [x]
        self.n += 1

    def mean(self) -> float | None:
        return math.fsum(self.partials) / self.n if self.n else None
