"""Ctrl+C and SIGTERM on the command line: the signal only asks the bake to stop, through the same
cancel the bake polls between photon batches, estimator chunks and written files, so it ends with
one line and exit code 130 instead of a KeyboardInterrupt traceback, and nothing half-written.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

EXIT_CODE = 130  # 128 + SIGINT, what shells expect of a program stopped by Ctrl+C


class SignalCancel:
    """A cancel callable for `bake.compute_many` and `bake.write_many`, set by a signal."""

    def __init__(self):
        self.event = threading.Event()
        self.signal = None

    def __call__(self) -> bool:
        return self.event.is_set()

    def set(self, signum=None) -> None:
        self.signal = signum
        self.event.set()


@contextmanager
def cancel_on_signals(signals=(signal.SIGINT, signal.SIGTERM)):
    """Within the block, SIGINT and SIGTERM set the yielded cancel instead of raising. Signal
    handlers exist on the main thread only; elsewhere the cancel is yielded unhooked."""
    cancel = SignalCancel()
    if threading.current_thread() is not threading.main_thread():
        yield cancel
        return
    previous = {}
    try:
        for signum in signals:
            previous[signum] = signal.signal(signum, lambda s, frame: cancel.set(s))
        yield cancel
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
