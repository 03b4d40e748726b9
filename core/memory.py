"""How much memory a reader may still allocate, checked before a large allocation.

A reader that knows its size up front (Parquet metadata holds the row counts)
compares what it will need with what the machine (and this process's limits)
can give, and refuses with one line instead of being killed by the kernel's
out-of-memory killer half-way.
"""

from __future__ import annotations

import contextlib
import os
import resource
from pathlib import Path

from eosp.errors import InputError

GiB = 1024 ** 3


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_available() -> int | None:
    """Room left under a cgroup v2 memory limit (containers), when there is one."""
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit == "max":
            return None
        return int(limit) - int(Path("/sys/fs/cgroup/memory.current").read_text().strip())
    except (OSError, ValueError):
        return None


def _address_space_available() -> int | None:
    """Room left under RLIMIT_AS (e.g. ``prlimit --as``), when it is set."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return soft - pages * os.sysconf("SC_PAGE_SIZE")


def available_bytes() -> int | None:
    """The least of MemAvailable, the cgroup room and the address-space room (None when unknown)."""
    vals = [v for v in (_meminfo_available(), _cgroup_available(), _address_space_available()) if v is not None]
    return min(vals) if vals else None


MAX_BYTES: int | None = None  # the user's own ceiling (--max-memory-gb), on top of what the machine has


def set_max_memory_gb(gb: float | None) -> None:
    """Set (or clear, with None or 0) the ceiling every :func:`require_memory` also applies (--max-memory-gb)."""
    global MAX_BYTES
    MAX_BYTES = int(gb * GiB) if gb else None


@contextlib.contextmanager
def memory_ceiling(gb: float | None):
    """The ceiling for one command (``with memory_ceiling(ns.max_memory_gb): ...``), the previous one restored
    afterwards: a command called in-process (tests, notebooks) leaves no limit behind for the next caller."""
    global MAX_BYTES
    before = MAX_BYTES
    set_max_memory_gb(gb)
    try:
        yield
    finally:
        MAX_BYTES = before


def require_memory(file: object, need: int, what: str) -> None:
    """Raise a one-line :class:`InputError` when `need` bytes are clearly not available, or exceed the user's
    ceiling (:func:`set_max_memory_gb`): before the work, with the estimate, instead of the kernel's OOM killer."""
    if MAX_BYTES is not None and need > MAX_BYTES:
        raise InputError(file, f"too large for --max-memory-gb {MAX_BYTES / GiB:g}: {what} needs about "
                               f"{need / GiB:.1f} GiB")
    have = available_bytes()
    if have is not None and need > have:
        raise InputError(file, f"too large for the memory available: {what} needs about {need / GiB:.1f} GiB, "
                               f"{max(have, 0) / GiB:.1f} GiB available")


def peak_rss_gb() -> float | None:
    """This process's peak resident memory so far (VmHWM), in GB; None where /proc does not say."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024 / 1e9
    except (OSError, ValueError, IndexError):
        pass
    return None


def _children(pid: int) -> list[int]:
    """`pid` and every process below it (from /proc's parent links; Ray's raylet, GCS and actors are under the
    driver that started the local cluster)."""
    kids: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        kids.setdefault(ppid, []).append(int(d.name))
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo += kids.get(p, [])
    return out


def tree_pss(pid: int) -> dict[str, int]:
    """Proportional set size (bytes) of `pid` and its descendants, by process name: each shared page (the object
    store's shared memory, forked copies) counted once over the processes that map it, so the sum is the memory the
    tree takes.  Names as /proc/PID/comm says (Ray's actors are ``ray::PassWorker``)."""
    out: dict[str, int] = {}
    for p in _children(pid):
        try:
            name = Path(f"/proc/{p}/comm").read_text().strip()
            for line in Path(f"/proc/{p}/smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    out[name] = out.get(name, 0) + int(line.split()[1]) * 1024
                    break
        except (OSError, ValueError, IndexError):
            continue
    return out
