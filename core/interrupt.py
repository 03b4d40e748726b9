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
