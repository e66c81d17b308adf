"""Ctrl-C and SIGTERM during ``farsighter train``: the loop finishes the step it is in, saves a
checkpoint as a periodic one would (with the replay), and stops with
:class:`~farsighter.errors.Interrupted`; ``--resume`` continues from there.

:func:`stop_on_signal` replaces the two signals' handlers while it is entered (the CLI enters it
around training; a library caller that does not keeps Python's own behaviour). The handler only
records the signal; the loops read it with :func:`requested` after each step. A second signal
stops at once (Interrupted raised where the program is), keeping the last checkpoint."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

from farsighter.errors import Interrupted

SIGNALS = (signal.SIGINT, signal.SIGTERM)

_requested = 0  # the signal that asked the loop to stop; 0: none


def requested() -> int:
    """The signal that asked training to stop (SIGINT or SIGTERM), or 0."""
    return _requested


def signal_name(signum: int) -> str:
    return signal.Signals(signum).name


@contextmanager
def stop_on_signal() -> Iterator[None]:
    """While entered, SIGINT and SIGTERM ask the training loop to stop after its step (see the
    module). Only in the main thread, where Python delivers signals; a signal the process was
    told to ignore (``nohup``, a background job's SIGINT) stays ignored. The previous handlers
    are restored and the request cleared on exit."""
    global _requested
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handle(signum: int, frame: FrameType | None) -> None:
        global _requested
        if _requested:
            raise Interrupted(
                signum,
                f"interrupted ({signal_name(signum)}) again, before the checkpoint was saved; "
                "the run directory keeps its last one; continue the run with --resume",
            )
        _requested = signum

    previous = {
        signum: signal.signal(signum, handle)
        for signum in SIGNALS
        if signal.getsignal(signum) is not signal.SIG_IGN
    }
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)
        _requested = 0


def interrupted(step: int, where: str) -> Interrupted:
    """The error a loop raises after saving at ``step`` on a requested stop; ``where``: the run
    directory (or directories) that hold the checkpoint."""
    signum = _requested or signal.SIGINT
    return Interrupted(
        signum,
        f"interrupted ({signal_name(signum)}) at step {step:,}; saved a checkpoint in {where}; "
        "continue the run with --resume",
    )


def stop_before_start() -> None:
    """Raise :class:`Interrupted` when a stop was asked before the loop wrote anything (while
    the environments were made, say): there is nothing to save."""
    if _requested:
        raise Interrupted(
            _requested,
            f"interrupted ({signal_name(_requested)}) before training started; nothing was written",
        )
