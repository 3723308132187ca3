"""One BLAS thread for the small dense linear algebra of thermctl (and the other
process-wide settings that threads and repeated evaluations need: the heap, warnings).

The matrices here are small (tens to a few hundred states): BLAS threads only fight
each other and other processes. Measured on the 2-core CI machine under load, 150
exact steps of a 55-state model took 38.9 s with threaded OpenBLAS and 0.54 s with
one thread, and one 61×61 LU solve of the grey-box filter 20 ms against 0.3 ms.

This is the only such helper: model, estimate, greybox and testbed all call
:func:`single_thread_blas`.

The same call keeps freed memory in the process (:func:`keep_heap`): a gradient of the
likelihood allocates and frees tens of megabytes of CasADi work arrays, and glibc's default
returns each large block to the system, so the next call page-faults it in again.
Measured on the demo (7 zones, 61 states): one gradient 71 → 52 ms; the whole demo 37 → 28 s
of wall time, system time 7.4 → 0.5 s.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading
import warnings

from threadpoolctl import ThreadpoolController

__all__ = ["single_thread_blas", "keep_heap", "ignore_warnings", "record_warnings"]

_CONTROLLER = None
_HEAP_SET = False

# glibc mallopt parameters
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3


def keep_heap() -> bool:
    """Let glibc keep freed blocks up to 256 MB instead of returning them to the system.

    Blocks up to 32 MB (glibc's largest threshold) come from the heap rather than from a
    fresh ``mmap``, and up to 256 MB of free heap stay mapped. Once per process; a no-op
    elsewhere than glibc or when the user set ``MALLOC_MMAP_THRESHOLD_`` themselves.

    Returns
    -------
    bool
        Whether the settings were applied (now or before).
    """
    global _HEAP_SET
    if _HEAP_SET:
        return True
    _HEAP_SET = True
    if os.environ.get("MALLOC_MMAP_THRESHOLD_") or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        ok = (libc.mallopt(_M_MMAP_THRESHOLD, 32 << 20) == 1
              and libc.mallopt(_M_TRIM_THRESHOLD, 256 << 20) == 1
              and libc.mallopt(_M_TOP_PAD, 64 << 20) == 1)
    except (OSError, AttributeError):
        return False
    return bool(ok)


def _worker_thread() -> bool:
    return threading.current_thread() is not threading.main_thread()


def single_thread_blas():
    """Context manager limiting BLAS to one thread.

    Only from the main thread: the limit is process-wide, so worker threads (the grid
    search's) leave it to their caller. The library scan is done once, because
    ``threadpool_limits`` rescans the loaded libraries on every call.
    """
    global _CONTROLLER
    keep_heap()
    if _worker_thread():
        return contextlib.nullcontext()
    if _CONTROLLER is None:
        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=1)


# ---------------------------------------------------------------------- warnings in threads
@contextlib.contextmanager
def ignore_warnings(*categories):
    """``warnings.simplefilter("ignore", c)`` for each category inside, in the main thread.

    In any other thread: nothing. The filters are process-wide and ``catch_warnings`` is not
    thread-safe: two threads' contexts that close out of order leave the process with the
    other's filters and ``showwarning`` for good. Code that runs fits in threads holds one
    such context in the main thread around them (:meth:`LikelihoodScorer.fit_many`).
    """
    if _worker_thread():
        yield
        return
    with warnings.catch_warnings():
        for c in categories:
            warnings.simplefilter("ignore", c)
        yield


@contextlib.contextmanager
def record_warnings():
    """``warnings.catch_warnings(record=True)`` (every warning recorded) in the main thread;
    in another thread an empty list, and the warnings go to the process-wide filters (see
    :func:`ignore_warnings`)."""
    if _worker_thread():
        yield []
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught
