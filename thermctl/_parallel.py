"""Run independent tasks on local processes: the one pool of the local problems and the
stability resamples."""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed

from .errors import EstimationError

__all__ = ["run_tasks"]


def run_tasks(fn, tasks, *, workers: int | None = None, order=None, on_done=None) -> list:
    """``fn(*task)`` for every task, serially or on a process pool.

    Parameters
    ----------
    fn : callable
        Picklable (a module-level function) when ``workers > 1``.
    tasks : list of tuple
        Arguments of each call.
    workers : int, optional
        Processes (default: every core); 1 runs in this process.
    order : list of int, optional
        Submission order of the task indices (e.g. largest first, so that the last task to
        start is a short one); default: as given.
    on_done : callable, optional
        ``on_done(i, result)`` as each task finishes (in finishing order).

    Returns
    -------
    list
        The results in the order of ``tasks``.
    """
    n = len(tasks)
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise EstimationError(f"workers must be >= 1, found {workers}")
    order = list(range(n)) if order is None else list(order)
    results = {}

    def done(i, res):
        results[i] = res
        if on_done is not None:
            on_done(i, res)

    if workers == 1 or n <= 1:
        for i in order:
            done(i, fn(*tasks[i]))
    else:
        with ProcessPoolExecutor(max_workers=min(workers, n)) as pool:
            futs = {pool.submit(fn, *tasks[i]): i for i in order}
            for fut in as_completed(futs):
                done(futs[fut], fut.result())
    return [results[i] for i in range(n)]
