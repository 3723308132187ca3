"""One BLAS thread for the small dense linear algebra of thermctl.

The matrices here are small (tens to a few hundred states): BLAS threads only fight
each other and other processes. Measured on the 2-core CI machine under load, 150
exact steps of a 55-state model took 38.9 s with threaded OpenBLAS and 0.54 s with
one thread, and one 61×61 LU solve of the grey-box filter 20 ms against 0.3 ms.

This is the only such helper: model, estimate, greybox and testbed all call
:func:`single_thread_blas`.
"""

from __future__ import annotations

import contextlib
import threading

from threadpoolctl import ThreadpoolController

__all__ = ["single_thread_blas"]

_CONTROLLER = None


def single_thread_blas():
    """Context manager limiting BLAS to one thread.

    Only from the main thread: the limit is process-wide, so worker threads (the grid
    search's) leave it to their caller. The library scan is done once, because
    ``threadpool_limits`` rescans the loaded libraries on every call.
    """
    global _CONTROLLER
    if threading.current_thread() is not threading.main_thread():
        return contextlib.nullcontext()
    if _CONTROLLER is None:
        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=1)
