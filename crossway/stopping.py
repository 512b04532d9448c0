"""Ctrl-C and SIGTERM for the long loops of ``crossway pretrain`` and ``crossway evaluate``.

A Python signal handler that raises runs wherever the main thread is at the time. When that is a
finalizer (a ``__del__``, a weakref callback, a generator closed by the garbage collector),
Python swallows the exception and prints only "Exception ignored in ...", and a loop that relies
on the exception alone goes on as if no signal had come. ``StopRequest`` raises at once, as the
default handler does, and also remembers the signal, so the loop's own ``check`` between steps
stops it all the same.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator


class StopRequest:
    """The handler of SIGINT and SIGTERM during a loop: raises KeyboardInterrupt at once (or, for
    SIGTERM with ``sigterm_exits``, SystemExit(128 + SIGTERM), a killed process's status) and
    remembers the signal for ``check``."""

    def __init__(self, sigterm_exits: bool = False) -> None:
        self.sigterm_exits = sigterm_exits
        self.signal: int | None = None

    def exception(self) -> BaseException:
        if self.signal == signal.SIGTERM and self.sigterm_exits:
            return SystemExit(128 + signal.SIGTERM)
        return KeyboardInterrupt()

    def __call__(self, signum, _frame) -> None:
        self.signal = signum
        raise self.exception()

    def check(self) -> None:
        """Raises, if a stop signal came, what the handler raised: it may have been swallowed."""
        if self.signal is not None:
            raise self.exception()


@contextmanager
def stop_handlers(stop: StopRequest) -> Iterator[StopRequest]:
    """``stop`` handles SIGTERM, and SIGINT unless the process ignores it (a command started in
    the background by a shell) or has a handler of its own, until the block ends; then the former
    handlers are back. Off the main thread (which alone may set handlers) it changes nothing."""
    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, stop)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, stop)
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
