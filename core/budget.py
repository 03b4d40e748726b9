"""A solve's time budget: one object for "how long may this still run", instead of deadlines, seconds left and
stop flags spelled differently in every phase.

A :class:`Budget` is an instant on this process's ``time.perf_counter()`` clock (infinite: no limit).  It is made
once from the user's ``--time-limit`` (:meth:`Budget.of`, counted from when the problem was read), asked
:meth:`~Budget.expired` between steps and :meth:`~Budget.left` by a sub-solver that takes seconds, narrowed for a
sub-solve (:meth:`~Budget.cap`, :meth:`~Budget.less`), and sent to another process as the seconds it has left
(:meth:`~Budget.wire`: an instant means nothing on another machine's clock), which makes it a budget again with
:meth:`Budget.of`.  The command line and the configs keep ``time_limit``: seconds from the start, None for none.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass


@dataclass(frozen=True)
class Budget:
    """Time until `end` (a ``time.perf_counter()`` instant; ``inf``: no limit)."""

    end: float = math.inf

    @classmethod
    def of(cls, seconds: float | None, start: float | None = None) -> Budget:
        """`seconds` from `start` (a ``time.perf_counter()`` instant; now when None); None: no limit."""
        if seconds is None:
            return UNLIMITED
        return cls((time.perf_counter() if start is None else start) + seconds)

    @classmethod
    def spent(cls) -> Budget:
        """A budget that has run out (after Ctrl-C: what still runs stops at its first check)."""
        return cls(time.perf_counter())

    @property
    def limited(self) -> bool:
        return self.end != math.inf

    def expired(self) -> bool:
        """Whether the end has passed (never, without a limit)."""
        return self.limited and time.perf_counter() > self.end

    def left(self) -> float:
        """Seconds to the end, never below 0 (``inf`` without a limit)."""
        return max(0.0, self.end - time.perf_counter()) if self.limited else math.inf

    def cap(self, seconds: float) -> Budget:
        """This budget, or `seconds` from now when that ends first (a sub-solve's own limit)."""
        return Budget(min(self.end, time.perf_counter() + seconds))

    def less(self, seconds: float) -> Budget:
        """This budget ending `seconds` earlier (time kept for the steps after it)."""
        return Budget(self.end - seconds) if self.limited else self

    def wire(self) -> float | None:
        """The form sent to another process: seconds left, None without a limit (:meth:`of` makes it a budget
        again there, on that process's clock)."""
        return self.left() if self.limited else None


UNLIMITED = Budget()
