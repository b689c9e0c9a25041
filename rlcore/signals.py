"""Ctrl-C and ``kill`` during training: both end a run with a checkpoint (:func:`stop_on_signals`), and a checkpoint
being written is written whole (:func:`signals_held`)."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any


def stop_on_signals(once: bool = False) -> None:
    """Make SIGTERM (a ``kill``, a job scheduler) and SIGINT end a run as Ctrl-C does: a KeyboardInterrupt, on
    which every ``train`` saves a checkpoint before it stops.

    SIGINT is set too, even where it arrives ignored: a shell starts background jobs (``cmd &``) with SIGINT
    ignored, and Python then keeps it ignored, so ``kill -INT`` would do nothing to such a run. With ``once``
    (pool workers, which may receive Ctrl-C from the terminal and the parent's forwarded signal both), the first
    signal interrupts and later ones are ignored, so that the checkpoint it triggers is not cut short.
    """
    def interrupt(signum: int, frame: Any) -> None:
        if once:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, interrupt if once else signal.default_int_handler)


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Inside, a SIGINT or SIGTERM whose handler is Python's (one that would interrupt) is held back: when the block
    ends, that handler runs as if the signal had just come (a KeyboardInterrupt, a stop request), so that what the
    block writes is written whole. Only the main thread can hold signals; elsewhere nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    handlers = {sig: h for sig, h in handlers.items() if callable(h)}
    for sig in handlers:
        signal.signal(sig, lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    for signum in held:  # the block ended normally: the signals it held back take effect now, in order
        handlers[signum](signum, None)
