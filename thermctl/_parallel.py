"""Run independent tasks on local processes (the one pool of the local problems and the
stability resamples) or on threads (a whole building's trial fits and intervals, and the
:class:`ThreadPool` of a search's backward pass, whose next tasks are known only as the
current ones finish)."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed

from ._blas import single_thread_blas
from .errors import EstimationError

__all__ = ["run_tasks", "thread_map", "worker_count", "ThreadPool"]


def worker_count(workers: int | None) -> int:
    """``workers``, or every core when it is None."""
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise EstimationError(f"workers must be >= 1, found {workers}")
    return workers


def thread_map(fn, items, threads: int = 1) -> list:
    """``[fn(x) for x in items]``, ``threads`` at a time in threads, with one BLAS thread.

    For CasADi evaluations and BLAS, which release the GIL (two likelihood gradients in two
    threads: 4.4 s against 8.2 s one after the other). ``fn`` must not enter a
    ``warnings.catch_warnings`` context (not thread-safe; see
    :func:`thermctl._blas.ignore_warnings`): the caller holds one around the call.
    """
    items = list(items)
    if threads <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    with single_thread_blas(), ThreadPoolExecutor(max_workers=min(threads, len(items))) as pool:
        return list(pool.map(fn, items))


class ThreadPool:
    """Tasks on a fixed number of threads, submitted one by one, each of which can be stopped.

    ``submit(fn, *args)`` calls ``fn(*args, stop=event)``: a task that polls ``event``
    (:meth:`threading.Event.is_set`) can be told to give up (:meth:`cancel`). For work whose
    next tasks are known only as the current ones finish: the backward pass of a search
    starts the fits of the round it expects next on a thread the current round's last fits
    leave free (:func:`thermctl.structure.search.search_edges`). Not thread-safe itself:
    submit, cancel and close from one thread.

    Parameters
    ----------
    threads : int
    """

    def __init__(self, threads: int):
        self.threads = worker_count(threads)
        self._ex = ThreadPoolExecutor(max_workers=self.threads, thread_name_prefix="thermctl-pool")
        self._open = set()          # submitted, not done (queued or running)
        self._lock = threading.Lock()

    def submit(self, fn, *args, **kwargs):
        """``concurrent.futures.Future`` of ``fn(*args, stop=event, **kwargs)``; the event is
        the future's ``stop`` attribute."""
        stop = threading.Event()
        fut = self._ex.submit(fn, *args, stop=stop, **kwargs)
        fut.stop = stop
        with self._lock:
            self._open.add(fut)
        fut.add_done_callback(self._closed)
        return fut

    def _closed(self, fut):
        with self._lock:
            self._open.discard(fut)

    def idle(self) -> bool:
        """Whether a thread would start a task submitted now (fewer open tasks than threads)."""
        # done but not yet called back: Future.set_result wakes the waiters first
        with self._lock:
            return sum(1 for f in self._open if not f.done()) < self.threads

    @staticmethod
    def cancel(fut) -> None:
        """Drop ``fut`` if it has not started, else tell it to stop (its ``stop`` event)."""
        fut.stop.set()
        fut.cancel()

    def close(self) -> None:
        """Stop every open task (:meth:`cancel`) and wait for the threads to end."""
        with self._lock:
            open_ = list(self._open)
        for fut in open_:
            self.cancel(fut)
        self._ex.shutdown(wait=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


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
    workers = worker_count(workers)
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
