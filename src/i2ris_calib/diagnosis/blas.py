"""One BLAS thread for the diagnosis's many small least-squares steps."""

from __future__ import annotations

import contextlib

try:
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover - optional dependency
    threadpool_limits = None


def single_threaded_blas():
    """Context limiting BLAS to one thread (threadpoolctl), a no-op without it.

    The diagnosis runs thousands of small least-squares steps (Jacobians of
    ~10^3 x 13); multi-threaded BLAS only adds synchronisation to their SVDs and,
    on a loaded machine, made them ~10x slower (measured: 27 s vs 2.5 s per
    diagnosis on 2 shared cores).
    """
    if threadpool_limits is None:  # pragma: no cover - optional dependency
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")
