"""Candidate air paths: which end counts as unmeasured (the reason tag users read)."""

from thermctl.local import local_problems
from thermctl.structure.search import _cand
from thermctl.testbed import generate


def test_a_measured_neighbour_outside_a_local_problem_is_not_an_unmeasured_end():
    tb = generate("corridor", zones=7, days=1, seed=1)
    spec = tb.spec
    hall = [z for z in spec.zone_names if z not in spec.measured_zones]
    assert hall, "the corridor testbed has an unmeasured hallway"
    p = local_problems(spec)[0]
    nb = [c for c in p.candidates if (c[1] if c[0] == p.zone else c[0]) in p.spec.boundary]
    assert nb, "no candidate to a measured neighbour in this local problem"
    assert not any(_cand(p.spec, c).unmeasured for c in nb)
    # a pair with the hallway is one (it has no temperature column anywhere)
    c = _cand(spec, (spec.measured_zones[0], hall[0], 3.0))
    assert c.unmeasured
