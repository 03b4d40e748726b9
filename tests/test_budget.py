"""The time budget (eosp.budget): one object for how long a solve may still run."""

import math
import time

from eosp.budget import UNLIMITED, Budget


def test_no_limit_never_runs_out_and_goes_as_none():
    b = Budget.of(None)
    assert b is UNLIMITED and not b.limited and not b.expired()
    assert b.left() == math.inf and b.wire() is None
    assert b.less(5.0) is b  # nothing to keep back from no limit
    assert Budget.of(b.wire()) is UNLIMITED  # the wire form comes back as no limit
    assert b.cap(0.5).limited and b.cap(0.5).left() <= 0.5  # a sub-solve's own limit


def test_a_limit_counts_from_its_start_and_runs_out():
    t0 = time.perf_counter()
    b = Budget.of(0.05, start=t0)
    assert b.limited and b.end == t0 + 0.05 and 0.0 < b.left() <= 0.05
    time.sleep(0.06)
    assert b.expired() and b.left() == 0.0  # never below 0
    assert Budget.of(10.0, start=t0 - 20.0).expired()  # counted from when the problem was read, not from now
    assert Budget.spent().expired() or Budget.spent().left() == 0.0


def test_cap_less_and_wire_only_narrow():
    b = Budget.of(100.0)
    assert b.cap(1.0).left() <= 1.0 and b.cap(1000.0).end == b.end  # the earlier end wins
    assert b.less(30.0).end == b.end - 30.0
    w = b.wire()
    assert 99.0 < w <= 100.0
    again = Budget.of(w)  # on another process's clock: about the same seconds left
    assert abs(again.left() - b.left()) < 0.5
