"""The backward pass starts the next round's trials on a thread the current round leaves free.

A table scorer gives exact criteria, and its fits take set times, so which trials run when is
known: the tests check that the next round's trials start before the round ends, that a
round takes them only when it is the round they were started for (from that very fit), that
a wrong guess is stopped and never counted, and that the search is the serial one.
"""

from __future__ import annotations

import contextlib
import itertools
import random
import threading
import time
import zlib

import pytest

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
        # the fit object carries the structure it fitted (a new object every fit); the
        # criterion carries a trace of the start, so a fit taken from another start than the
        # serial search's shows in the values
        return (list(edges), object()), (100.0 - sum(self.gains[c.name] for c in edges)
                                         + _start_mark(warm))

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


def _start_mark(warm) -> float:
    """A criterion offset [-] below 1e-3 that depends on the structure a fit started from."""
    if warm is None:
        return 0.0
    return (zlib.crc32(repr(sorted(c.name for c in warm[0])).encode()) % 1000) * 1e-6


def _search(scorer, workers):
    return search_edges([A, B, C, D], scorer, direction="backward", margin=10.0,
                        workers=workers)


def _summary(r):
    return ([c.name for c in r.edges],
            [(s.action, s.edge, s.value, s.delta, s.edges, s.screened, s.note) for s in r.path],
            list(r.trials), [v[1] for v in r.trials.values()], r.reasons)


def _same(r1, r2):
    assert _summary(r1) == _summary(r2)


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


class WeakScorer(TimedScorer):
    """Also a daily test: an edge in ``weak`` never holds (its t is minus its name's length),
    so the backward pass removes it before the cheapest removal; a fit of ``fail`` raises."""

    def __init__(self, gains, slow, weak=(), fail=None):
        super().__init__(gains, slow)
        self.weak, self.fail = set(weak), fail

    def run(self, edges, warm=None, stop=None):
        if frozenset(c.name for c in edges) == self.fail:
            raise ValueError("a real error in a fit")
        return super().run(edges, warm, stop)

    def consistent(self, small, big):
        (name,) = {c.name for c in big[0]} - {c.name for c in small[0]}
        ok = name not in self.weak
        return ok, 1.0 if ok else -float(len(name)), ""


def test_random_searches_on_two_and_three_threads_are_the_serial_one():
    """Seeded random buildings of 1-6 candidates, gains below and far above the margin,
    edges whose daily test fails (picked before the cheapest removal), recheck off, 2 and
    10, fit times of 1-20 ms: the path, its values, the trials (in order) and reasons, and
    the number of fits counted are the serial search's on 2 and 3 threads."""
    rng = random.Random(3)
    for _ in range(25):
        n = rng.randint(1, 6)
        cs = [cand(f"z{i}", f"z{i + 1}") for i in range(n)]
        gains = {c.name: rng.choice([rng.uniform(-30, 30), rng.uniform(50, 600)]) for c in cs}
        weak = [c.name for c in cs if rng.random() < 0.2]
        recheck = rng.choice([None, 10.0, 2.0])
        slow = {frozenset(c.name for c in sub): rng.choice([0.001, 0.002, 0.02])
                for r in range(n + 1) for sub in itertools.combinations(cs, r)}
        out = []
        for w in (1, 2, 3):
            sc = WeakScorer(gains, slow, weak)
            res = search_edges(cs, sc, direction="backward", margin=10.0, workers=w,
                               recheck=recheck)
            out.append((_summary(res), sc.n_fits))
        assert out[1] == out[0] and out[2] == out[0], (n, gains, weak, recheck)


@pytest.mark.parametrize("ahead", [False, True])
def test_an_error_in_a_trial_fit_reaches_the_caller(ahead):
    """A fit that raises (in a round, or one started ahead and then taken) stops the search
    with that error, and no thread is left running."""
    gains = {A.name: 5.0, B.name: 500.0, C.name: 40.0, D.name: 300.0}
    without_c = frozenset({A.name, B.name, D.name})
    # ahead: {B, D} is the next round's trial, started while the slow round-1 trial runs
    fail = frozenset({B.name, D.name}) if ahead else without_c
    sc = WeakScorer(gains, {without_c: 0.2}, fail=fail)
    before = threading.active_count()
    with pytest.raises(ValueError, match="a real error"):
        _search(sc, 2)
    assert threading.active_count() == before
