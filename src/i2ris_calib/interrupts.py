"""Ctrl-C (SIGINT) that never tears compiled code apart.

CPython's SIGINT handler raises ``KeyboardInterrupt`` in the main thread at the next
point where Python code runs. Two such points are unsafe:

* **numba's result boxing.** A numba-compiled function that returns arrays converts
  them to Python objects in C, calling back into Python for each array type
  (``numba.core.serialize._numba_unpickle``). A ``KeyboardInterrupt`` raised in that
  callback is not checked there: the remaining results are boxed with the exception
  set, and the call ends in ``SystemError: ... returned a result with an exception
  set`` or a segmentation fault (compensate of a 1e6-sample target, Ctrl-C 3-8 s in:
  SIGSEGV; numba/numba#2324). A Ctrl-C while compiled code runs is always handled
  there, at its return, because compiled code runs no Python code before that.
* **a** ``__del__`` (llvmlite frees its objects in one): an exception raised there is
  printed as "Exception ignored" and dropped, and the command runs on.

:func:`sigint_guard` (installed by the CLI) replaces Python's default handler with
one that raises ``KeyboardInterrupt`` like it, except in those places, where it
re-delivers the signal so that it is raised a moment later, at the first safe point
(after the compiled call has returned). :func:`deferred` holds a Ctrl-C back for the
length of a block, for library code that calls a compiled function without the CLI.
"""

from __future__ import annotations

import _thread
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

#: Modules whose Python code compiled code calls back into while it converts results.
CALLBACK_MODULES = frozenset({"numba.core.serialize"})


def unsafe_frame(frame: FrameType | None) -> bool:
    """Whether a ``KeyboardInterrupt`` raised in ``frame`` would corrupt its caller or
    be dropped: the frame or one that called it runs in :data:`CALLBACK_MODULES` or is
    a ``__del__``."""
    while frame is not None:
        if frame.f_code.co_name == "__del__":
            return True
        if frame.f_globals.get("__name__") in CALLBACK_MODULES:
            return True
        frame = frame.f_back
    return False


#: Delay (s) before a held-back SIGINT is delivered again (:func:`_redeliver_later`).
REDELIVER_S = 0.005


def _redeliver() -> None:
    """Trip SIGINT again: its handler runs at the next point Python checks for signals
    (which may be right after this call: never from a handler, see
    :func:`_redeliver_later`)."""
    _thread.interrupt_main(signal.SIGINT)


def _redeliver_later() -> None:
    """Trip SIGINT again from a helper thread in :data:`REDELIVER_S`. Tripping it from
    the handler itself would run the handler again at once, inside itself, still above
    the unsafe frame: an endless recursion."""
    timer = threading.Timer(REDELIVER_S, _redeliver)
    timer.daemon = True
    timer.start()


def safe_sigint_handler(signum: int, frame: FrameType | None) -> None:
    """SIGINT handler: ``KeyboardInterrupt``, re-delivered later where unsafe."""
    if unsafe_frame(frame):
        _redeliver_later()
        return
    raise KeyboardInterrupt


def _unraisable_hook(previous):
    """A ``sys.unraisablehook`` that re-delivers a dropped ``KeyboardInterrupt`` (one
    raised in a callback that can only print it) instead of printing it."""

    def hook(unraisable) -> None:
        if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
            _redeliver_later()
            return
        previous(unraisable)

    return hook


@contextmanager
def sigint_guard(ignore_after: bool = False) -> Iterator[None]:
    """Run the block with :func:`safe_sigint_handler` as the SIGINT handler.

    Only in the main thread and only where Python's default handler is installed (a
    process started with SIGINT ignored stays so). ``KeyboardInterrupt`` still reaches
    the block's caller as usual.

    Parameters
    ----------
    ignore_after : bool
        Ignore SIGINT once the block has ended instead of restoring the previous
        handler: for a process whose result is decided (its outputs written), so that a
        Ctrl-C while the interpreter shuts down (where Python restores the default
        action: killed by SIGINT, no message) does not override it.
    """
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    previous_hook = sys.unraisablehook
    signal.signal(signal.SIGINT, safe_sigint_handler)
    sys.unraisablehook = _unraisable_hook(previous_hook)
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        signal.signal(signal.SIGINT, signal.SIG_IGN if ignore_after else signal.default_int_handler)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold a Ctrl-C back while the block runs; raise it (re-deliver SIGINT) when it ends.

    For a call into compiled code that returns arrays, from library code: it cannot
    be torn, and the interrupt follows right after it. Nothing to do outside the main
    thread, under :func:`sigint_guard` (already safe) or where SIGINT has no Python
    handler.
    """
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.getsignal(signal.SIGINT)
    if not callable(previous) or previous is safe_sigint_handler:
        yield
        return
    caught: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught:
            _redeliver()
