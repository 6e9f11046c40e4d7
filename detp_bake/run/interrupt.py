"""Ctrl+C and SIGTERM on the command line: the signal only asks the bake to stop, through the same
cancel the bake polls between photon batches, estimator chunks and written files, so it ends with
one line and exit code 130 instead of a KeyboardInterrupt traceback, and nothing half-written.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import time
from contextlib import contextmanager

EXIT_CODE = 130  # 128 + SIGINT, what shells expect of a program stopped by Ctrl+C
HOLD_ENV = "DETP_BAKE_TEST_HOLD"


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


def hold(phase: str, cancelled) -> None:
    """For tests of the above: with DETP_BAKE_TEST_HOLD=<phase> (write), the bake says so on
    stderr and waits here, up to a minute or until cancelled, so that a test can send its signal
    at a known point of the bake. Does nothing otherwise."""
    if os.environ.get(HOLD_ENV) != phase:
        return
    print(f"detp_bake: holding in {phase} ({HOLD_ENV})", file=sys.stderr, flush=True)
    end = time.monotonic() + 60.0
    while not cancelled() and time.monotonic() < end:
        time.sleep(0.02)
