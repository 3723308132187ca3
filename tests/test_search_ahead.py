"""The backward pass starts the next round's trials on a thread the current round leaves free.

A table scorer gives exact criteria, and its fits take set times, so which trials run when is
known: the tests check that the next round's trials start before the round ends, that a
round takes them only when it is the round they were started for (from that very fit), that
a wrong guess is stopped and never counted, and that the search is the serial one.
"""

from __future__ import annotations

import contextlib
import threading
import time

from thermctl._parallel import ThreadPool
from thermctl.structure.search import Candidate, search_edges


def cand(a, b):
    return Candidate(a, b, 3.0, False, False)


A, B, C, D = cand("a", "b"), cand("c", "d"), cand("a", "c"), cand("b", "d")


class TimedScorer:
    """Criterion = 100 − the sum of the structure's edges' gains; the fit of a structure in
    ``slow`` takes that long [s] (polling its stop event), every other one 0.01 s."""

    name = "bic"

    def __init__(self, gains, slow=None):
        self.gains, self.slow = gains, slow or {}
        self.lock = threading.Lock()
        self.log = []                   # (event, structure, warm structure, time)
        self.n_fits = 0
        self.t0 = time.perf_counter()

    def note(self, what, edges, warm):
        with self.lock:
            self.log.append((what, frozenset(c.name for c in edges),
                             None if warm is None else frozenset(c.name for c in warm[0]),
                             time.perf_counter() - self.t0))

    def fit(self, edges, warm=None):
        """The serial search's fit: counted."""
        self.n_fits += 1
        return self.run(edges, warm)

    def run(self, edges, warm=None, stop=None):
        self.note("start", edges, warm)
        key = frozenset(c.name for c in edges)
        end = time.perf_counter() + self.slow.get(key, 0.01)
        while time.perf_counter() < end:
            if stop is not None and stop.is_set():
                self.note("stopped", edges, warm)
                raise RuntimeError("stopped")
            time.sleep(0.002)
        self.note("end", edges, warm)
        # the fit object carries the structure it fitted (a new object every fit)
        return (list(edges), object()), 100.0 - sum(self.gains[c.name] for c in edges)

    def screen(self, edges, rest, fitted):
        return {c.name: -self.gains[c.name] for c in rest}

    @contextlib.contextmanager
    def pool(self, workers):
        with ThreadPool(workers) as threads:
            yield _Pool(self, threads)


class _Pool:
    def __init__(self, scorer, threads):
        self.scorer, self.threads = scorer, threads

    def submit(self, edges, warm):
        return self.threads.submit(self.scorer.run, list(edges), warm)

    def idle(self):
        return self.threads.idle()

    def cancel(self, fut):
        self.threads.cancel(fut)

    def result(self, fut):
        self.scorer.n_fits += 1
        return fut.result()


def _search(scorer, workers):
    return search_edges([A, B, C, D], scorer, direction="backward", margin=10.0,
                        workers=workers)


def _same(r1, r2):
    assert [c.name for c in r1.edges] == [c.name for c in r2.edges]
    assert [(s.action, s.edge, s.value) for s in r1.path] == \
        [(s.action, s.edge, s.value) for s in r2.path]


def test_the_next_round_starts_on_the_free_thread_and_is_taken():
    # A gains 5 (< margin 10): removed first; B, C, D gain 500, 40 and 300. Round 1 tries the
    # four removals; the one without C takes 0.4 s, so when the other three are done a
    # thread is free and the round after removing A is known as far as it can be: B and D
    # (costs 500 and 300, above 10 × margin) are not tried again, C (not finished) is, so
    # the one trial is {B, D}, warm from the fit of {B, C, D}
    gains = {A.name: 5.0, B.name: 500.0, C.name: 40.0, D.name: 300.0}
    without_c = frozenset({A.name, B.name, D.name})
    sc1 = TimedScorer(gains, {without_c: 0.4})
    serial = _search(sc1, 1)
    sc = TimedScorer(gains, {without_c: 0.4})
    got = _search(sc, 2)
    _same(serial, got)
    assert [c.name for c in got.edges] == [B.name, C.name, D.name]
    bd = frozenset({B.name, D.name})
    start = [t for what, key, warm, t in sc.log if what == "start" and key == bd]
    end_c = [t for what, key, warm, t in sc.log if what == "end" and key == without_c]
    assert len(start) == 1 and start[0] < end_c[0]          # started ahead, once
    warm = [w for what, key, w, t in sc.log if what == "start" and key == bd][0]
    assert warm == frozenset({B.name, C.name, D.name})
    # the guess was right: nothing stopped, every fit made was taken, as many as the serial
    # search made (start 1, round 1: 4, round 2: 1, the full round: 2 more)
    assert not [e for e in sc.log if e[0] == "stopped"]
    assert sc.n_fits == sc1.n_fits == 8
    assert sum(1 for e in sc.log if e[0] == "start") == 8


def test_a_wrong_guess_is_stopped_and_the_search_is_the_serial_one():
    # the removal finished first below the margin (A, cost +5) is not the one the round picks:
    # D's removal, slow, costs -20 (D gains -20: removing it improves the criterion). The
    # fit started for the round after removing A ({B, C} from the fit of {B, C, D}) is
    # stopped; the round after removing D fits {B, C} again, from the fit of {A, B, C}
    gains = {A.name: 5.0, B.name: 500.0, C.name: 400.0, D.name: -20.0}
    without_d = frozenset({A.name, B.name, C.name})
    sc1 = TimedScorer(gains, {without_d: 0.3})
    serial = _search(sc1, 1)
    # the guessed round's fit is slow, so that it is still running when stopped
    sc = TimedScorer(gains, {without_d: 0.3, frozenset({B.name, C.name}): 1.0})
    got = _search(sc, 2)
    _same(serial, got)
    assert D.name not in {c.name for c in got.edges}
    bc = frozenset({B.name, C.name})
    stopped = [(key, warm) for what, key, warm, t in sc.log if what == "stopped"]
    assert stopped == [(bc, frozenset({B.name, C.name, D.name}))]
    taken = [warm for what, key, warm, t in sc.log if what == "end" and key == bc]
    assert taken == [frozenset({A.name, B.name, C.name})]
    # the stopped fit was not counted: as many fits as the serial search
    assert sc.n_fits == sc1.n_fits
