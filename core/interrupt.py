"""Ctrl-C held back until the program is at a safe point.

A search that edits its plan in place (insert an observation, propagate the start times along a satellite's
sequence, journal the edit) is only consistent between edits: a ``KeyboardInterrupt`` raised by Python's handler
lands between any two bytecodes, and a plan caught half-way through an edit can be neither undone nor written.
:class:`HeldInterrupt` replaces the SIGINT handler for a block by one that only records the signal; the code polls
:attr:`HeldInterrupt.seen` where its state is whole and stops there; on leaving the block the previous handler is
back and, if a Ctrl-C came and the block did not stop for it, it is delivered then (the previous handler runs:
the ``eosp`` CLI's, Python's own ``KeyboardInterrupt``).

Outside the main thread (signal handlers cannot be set there) or where SIGINT is ignored, nothing is replaced and
:attr:`seen` stays false: behaviour as without the block.
"""

from __future__ import annotations

import _signal as signal  # the C module: signal.signal without its enum wrapping (a few µs a call)
from types import FrameType


class HeldInterrupt:
    """Context manager: SIGINT recorded in :attr:`seen` inside the block, delivered at its end.

    >>> with HeldInterrupt() as held:
    ...     while not held.seen and work_left():
    ...         one_whole_edit()
    """

    def __init__(self) -> None:
        self.seen = False
        self._previous = None
        self._installed = False

    def _record(self, signum: int, frame: FrameType | None) -> None:  # noqa: ARG002 - the signal handler's shape
        self.seen = True

    def __enter__(self) -> "HeldInterrupt":
        try:
            current = signal.getsignal(signal.SIGINT)
            if current != signal.SIG_IGN and current is not None:  # None: a handler not set from Python
                self._previous = signal.signal(signal.SIGINT, self._record)
                self._installed = True
        except ValueError:  # not the main thread: Python's own behaviour stays
            pass
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self._installed:
            return
        signal.signal(signal.SIGINT, self._previous)
        self._installed = False
        if self.seen and exc_type is None:
            self.deliver()

    def deliver(self) -> None:
        """Run the handler that was replaced, as the signal would have (raises ``KeyboardInterrupt`` for Python's
        handler and the CLI's)."""
        previous = self._previous
        if callable(previous):
            previous(signal.SIGINT, None)
        else:  # SIG_DFL: Python would have died of the signal; a KeyboardInterrupt is the catchable equivalent
            raise KeyboardInterrupt


_SEEN: list[bool] = []  # a Ctrl-C came during the running program (ProgramInterrupt)


def sigint_seen() -> bool:
    """Whether Ctrl-C came during the program :class:`ProgramInterrupt` runs: an error that follows it is the
    interrupt's (a library turned it into another error), never a figure or a traceback."""
    return bool(_SEEN)


class ProgramInterrupt:
    """Context manager around a whole program (the ``eosp`` command, a job): Ctrl-C raises ``KeyboardInterrupt`` as
    Python's own handler does and is remembered (:func:`sigint_seen`), because libraries turn it into other errors:
    numba's dispatcher returns ``SystemError(... returned a result with an exception set)`` when the interrupt lands
    inside a compiled call, a Ray task or actor that got the same SIGINT (a terminal sends it to the whole process
    group) fails with its own error.  A ``KeyboardInterrupt`` that lands in a C callback is dropped there by Python
    ('Exception ignored'); it is delivered again, to land in ordinary code.  An ignored SIGINT stays ignored; outside
    the main thread nothing is replaced."""

    def __enter__(self) -> "ProgramInterrupt":
        import sys

        _SEEN.clear()
        self._previous, self._unraisable = None, sys.unraisablehook
        sys.unraisablehook = self._swallowed
        try:
            if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                self._previous = signal.signal(signal.SIGINT, self._on_sigint)
        except ValueError:  # not the main thread: Python's handler stays
            self._previous = None
        return self

    @staticmethod
    def _on_sigint(signum: int, frame: FrameType | None) -> None:  # noqa: ARG004 - the signal handler's shape
        _SEEN.append(True)
        raise KeyboardInterrupt

    def _swallowed(self, u) -> None:
        if u.exc_type is KeyboardInterrupt:
            signal.raise_signal(signal.SIGINT)
        else:
            self._unraisable(u)

    def __exit__(self, exc_type, exc, tb) -> None:
        import sys

        sys.unraisablehook = self._unraisable
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)

    @property
    def seen(self) -> bool:
        return sigint_seen()
