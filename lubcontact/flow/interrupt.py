"""Stop a run cleanly on Ctrl-C or SIGTERM: between two steps, with a checkpoint.

:func:`stop_on_signals` installs, for the duration of a ``with`` block, handlers
of SIGINT and SIGTERM that only note the request (:func:`requested`);
:meth:`FlowRun.advance <lubcontact.flow.run.FlowRun.advance>` checks it before
each step and, when set, writes a checkpoint and raises :class:`Interrupted`.
So a signal never lands inside a solver (numba, Clarabel) or a file write: the
step under way finishes first. A second signal, for a step that takes too long,
restores the previous handlers and raises :class:`KeyboardInterrupt` at once
(no checkpoint for the steps since the last one). The previous handlers are
restored when the block ends. Blocks nest: an inner block (a run's
:meth:`~lubcontact.flow.run.FlowRun.advance` inside a sweep's or a script's
block) keeps the outer one's handlers and requests, so a signal received between
two runs still stops the next one.
"""
from __future__ import annotations

import pathlib
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = tuple(s for s in (getattr(signal, "SIGINT", None), getattr(signal, "SIGTERM", None))
                if s is not None)
EXIT_STATUS = 130
"""Exit status of a command stopped by a signal (128 + SIGINT, the shell's convention)."""

_requested: list[int] = []          # the signals received inside the outermost block
_depth = [0]                        # blocks open in the main thread


class Interrupted(Exception):
    """A run stopped between two steps at a signal's request.

    Attributes
    ----------
    step : int
        Steps done when it stopped.
    checkpoint : pathlib.Path or None
        The checkpoint written at that step (None: the run writes no files,
        e.g. the settling of a bed).
    what : str
        The run, in words (scene, model, angle).
    """

    def __init__(self, step: int, checkpoint: pathlib.Path | None, what: str):
        super().__init__(f"interrupted at step {step} ({what})")
        self.step, self.checkpoint, self.what = step, checkpoint, what

    def __reduce__(self) -> tuple:
        """Picklable with its fields (a sweep's worker process hands it to the parent)."""
        return type(self), (self.step, self.checkpoint, self.what)


def requested() -> bool:
    """Whether a stop was requested by a signal inside :func:`stop_on_signals`."""
    return bool(_requested)


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """Turn SIGINT and SIGTERM into a stop request for the duration of the block.

    Outside the main thread (where handlers cannot be installed) the block runs
    with the handlers as they are; inside an open block it adds nothing.
    """
    if threading.current_thread() is not threading.main_thread() or _depth[0]:
        yield
        return
    previous = {number: signal.getsignal(number) for number in SIGNALS}

    def restore() -> None:
        for number, handler in previous.items():
            signal.signal(number, handler)

    def handler(number: int, frame: FrameType | None) -> None:
        if _requested:                       # the second one: stop now
            restore()
            raise KeyboardInterrupt
        _requested.append(number)

    _requested.clear()
    for number in SIGNALS:
        signal.signal(number, handler)
    _depth[0] += 1
    try:
        yield
    finally:
        _depth[0] -= 1
        restore()
        _requested.clear()
