"""Ctrl-C held back for the moments that must not be cut in two.

A SIGINT that arrives inside :func:`sigint_held_back` stays pending and is delivered (as
KeyboardInterrupt) when the block ends. The command line uses it where an interruption
would not be clean:

* while Drake's extension modules load: their C++ initialization turns a KeyboardInterrupt
  into ``ImportError: initialization failed`` after logging a critical message;
* while a result folder is moved into place and recorded, so that an interrupted command
  knows whether its result was written;
* while worker processes start: they inherit the blocked signal and ignore it before they
  unblock it, so a Ctrl-C never prints a worker's traceback.

Standard library only: the command line imports it before anything heavy.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = ["record_sigint", "sigint_held_back", "sigint_received"]


# Whether a SIGINT arrived since record_sigint() was last called.
_received = threading.Event()


def _record_and_raise(signum, frame):
    _received.set()
    raise KeyboardInterrupt


def record_sigint() -> None:
    """Delivers SIGINT as KeyboardInterrupt, as Python does by default, and remembers
    that it came (a no-op outside the main thread).

    A KeyboardInterrupt raised while an extension converts its arguments (numpy checks
    for signals while it builds an array for a pybind11 call) reaches the caller as that
    call's TypeError instead: the command line then asks :func:`sigint_received`.
    """
    _received.clear()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, _record_and_raise)


def sigint_received() -> bool:
    """True when a SIGINT arrived since :func:`record_sigint`."""
    return _received.is_set()


@contextlib.contextmanager
def sigint_held_back() -> Iterator[None]:
    """Blocks SIGINT in this thread inside the block (a no-op outside the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)
