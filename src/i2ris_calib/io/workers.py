"""Worker process pools that Ctrl-C stops cleanly.

A Ctrl-C in a terminal sends SIGINT to the whole foreground process group, workers
included: each worker would print its own ``KeyboardInterrupt`` traceback (even while
still importing), and ``ProcessPoolExecutor`` would then wait for the running jobs to
finish. Here the workers are started with SIGINT ignored (a spawned interpreter
inherits the ignored disposition and installs no handler of its own), so only the main
process reacts: it terminates the workers, drops the pending jobs and re-raises
``KeyboardInterrupt``, which the CLI turns into its one-line message (exit 130).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import contextmanager


@contextmanager
def quiet_pool(
    max_workers: int, mp_context, jobs: list[tuple], initializer=None, initargs: tuple = ()
) -> Iterator[list[Future]]:
    """Start a process pool with SIGINT ignored in its workers and submit ``jobs``.

    Parameters
    ----------
    max_workers : int
    mp_context : multiprocessing context (``spawn``)
    jobs : list of tuples ``(function, *args)``
        Submitted at once, while SIGINT is ignored, so every worker starts ignoring it.
    initializer, initargs
        As for :class:`concurrent.futures.ProcessPoolExecutor`.

    Yields
    ------
    list of Future
        One per job, in order. On any exception in the ``with`` body (Ctrl-C included)
        the workers are terminated and pending jobs cancelled before it propagates.
    """
    main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        ex = ProcessPoolExecutor(
            max_workers, mp_context=mp_context, initializer=initializer, initargs=initargs
        )
        futures = [ex.submit(fn, *args) for fn, *args in jobs]
    finally:
        if main:
            signal.signal(signal.SIGINT, old)
    try:
        yield futures
    except BaseException:
        procs = list((getattr(ex, "_processes", None) or {}).values())
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.join(timeout=10)
        # wait for the executor's manager thread too: with shutdown(wait=False) it can
        # close its wake-up pipe while the interpreter's exit hook still writes to it,
        # which printed "Exception ignored ... Bad file descriptor" after the message
        ex.shutdown(wait=True, cancel_futures=True)
        raise
    ex.shutdown(wait=True)
