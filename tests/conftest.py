"""Shared fixtures: a small generic building and an independent reference for its matrices.

The small building (``small_spec_dict``) has

* three measured zones ``r1``, ``r2``, ``r3`` and an unmeasured ``hallway``;
* boundary nodes ``outside`` and ``ground``;
* walls given both as ``R``/``C`` and as ``area``/``u_value``/``heat_capacity``,
  including two parallel elements (wall and window) between ``r1`` and ``outside``;
* a zone with an explicit ``capacitance`` (``r3``);
* air-path distances, so convection edges can be added; ``small_network`` has one,
  ``r1``–``r3`` (not wall-connected, so it is the only link between them).

Fixtures return fresh or immutable objects: mutate only what a function-scoped
fixture gave you.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from thermctl.model import C_V_PAPER, RBAR_V_PAPER, ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.spec import spec_from_dict

REPO = Path(__file__).resolve().parents[1]
TWINHOUSE_SPEC = REPO.parent / "shared" / "data" / "twinhouse-n2" / "building.yaml"

SMALL_SPEC = {
    "name": "small",
    "zones": {
        "r1": {"volume": 60.0},
        "r2": {"volume": 45.0},
        "r3": {"volume": 50.0, "capacitance": 5.0e5},
        "hallway": {"volume": 120.0, "measured": False},
    },
    "boundary": ["outside", "ground"],
    "walls": [
        {"between": ["r1", "outside"], "R": [0.02, 0.06, 0.02], "C": [2.0e6, 2.0e6],
         "area": 12.0, "name": "r1-ext"},
        {"between": ["r1", "outside"], "R": [0.016, 0.047, 0.016], "C": [500.0, 500.0],
         "area": 3.0, "name": "r1-window"},
        {"between": ["r2", "outside"], "area": 10.0, "u_value": 0.5, "heat_capacity": 2.0e5},
        {"between": ["r3", "outside"], "R": [0.03, 0.09, 0.03], "C": [1.5e6, 1.5e6]},
        {"between": ["r1", "hallway"], "area": 8.0, "u_value": 2.0, "heat_capacity": 5.0e4},
        {"between": ["r2", "hallway"], "R": [0.02, 0.05, 0.02], "C": [4.0e5, 4.0e5]},
        {"between": ["r3", "hallway"], "R": [0.025, 0.07, 0.025], "C": [3.0e5, 3.0e5]},
        {"between": ["r1", "r2"], "R": [0.03, 0.08, 0.03], "C": [3.5e5, 3.5e5]},
        {"between": ["hallway", "ground"], "area": 20.0, "u_value": 0.8,
         "heat_capacity": 4.0e5},
    ],
    "distances": [
        {"between": ["r1", "r2"], "d": 4.0},
        {"between": ["r1", "r3"], "d": 9.0},
        {"between": ["r2", "r3"], "d": 5.0},
        {"between": ["r1", "hallway"], "d": 3.0},
        {"between": ["r3", "hallway"], "d": 3.5},
    ],
}
SMALL_CONVECTION = [("r1", "r3")]


@pytest.fixture
def small_spec_dict():
    """A fresh deep copy of the small spec as a plain dict (safe to mutate)."""
    return copy.deepcopy(SMALL_SPEC)


@pytest.fixture(scope="session")
def small_spec():
    """The small spec, validated (immutable)."""
    return spec_from_dict(copy.deepcopy(SMALL_SPEC), source="small.yaml")


@pytest.fixture(scope="session")
def small_network(small_spec):
    """The small building with one convection edge r1–r3 (d = 9 m)."""
    return ThermalNetwork(small_spec, convection=SMALL_CONVECTION)


@pytest.fixture
def small_model(small_network):
    """A ThermalModel of ``small_network`` at the paper's rbar_v, c_v (fresh per test)."""
    return ThermalModel(small_network, rbar_v=RBAR_V_PAPER, c_v=C_V_PAPER)


@pytest.fixture
def write_spec(tmp_path):
    """Factory: ``write_spec(content, name="building.yaml") -> Path``.

    ``content`` is a dict (dumped as YAML or JSON by the suffix) or raw text.
    """
    def _write(content, name="building.yaml"):
        path = tmp_path / name
        if isinstance(content, str):
            path.write_text(content)
        elif path.suffix.lower() == ".json":
            path.write_text(json.dumps(content))
        else:
            path.write_text(yaml.safe_dump(content, sort_keys=False))
        return path
    return _write


@pytest.fixture(scope="session")
def twinhouse_spec_path():
    """The real house spec (parallel walls between the same nodes); skipped if absent."""
    if not TWINHOUSE_SPEC.is_file():
        pytest.skip(f"{TWINHOUSE_SPEC} not available (shared data outside the repo)")
    return TWINHOUSE_SPEC


def _reference_linear_system(net, rbar_v, c_v, ms=None):
    """State matrices assembled by hand from the network's edges (no CasADi, no ``links()``).

    Parameters
    ----------
    net : ThermalNetwork
    rbar_v, c_v : float or array_like
        Convection parameters [K/(W m)], [J/K], shared or one per convection edge.
    ms : array_like, shape (n_zones,), optional
        Supply mass flow per zone [kg/s] (default 0).

    Returns
    -------
    A : ndarray, shape (n_states, n_states)
        ``df/dx`` at this flow [1/s].
    Bt : ndarray, shape (n_states, n_boundary)
        Boundary-temperature input matrix [1/s].
    cap : ndarray, shape (n_states,)
        Capacitance of every state [J/K].
    """
    spec = net.spec
    nz, nb, n = net.n_zones, len(net.boundary), net.n_states
    m = len(net.convection_edges)
    rbar_v = np.broadcast_to(np.asarray(rbar_v, dtype=float), (m,))
    c_v = np.broadcast_to(np.asarray(c_v, dtype=float), (m,))
    zi = {z: i for i, z in enumerate(net.zones)}
    bi = {b: j for j, b in enumerate(net.boundary)}
    cp = 1006.0 + 1860.0 * spec.w_s
    cap = np.empty(n)
    for i, z in enumerate(spec.zones):
        cap[i] = z.capacitance if z.capacitance is not None else \
            spec.capacity_multiplier * 1.2 * cp * z.volume
    G = np.zeros((n, n))       # conductance between states [W/K]
    Gb = np.zeros((n, nb))     # conductance state → boundary node [W/K]
    k_conv = 0
    for k, e in enumerate(net.edges):
        s1, s2 = nz + 2 * k, nz + 2 * k + 1
        if e.kind == "conduction":
            R, C = e.R, e.C
        else:
            R = (rbar_v[k_conv] * e.d,) * 3
            C = (c_v[k_conv],) * 2
            k_conv += 1
        cap[s1], cap[s2] = C
        for end, s, r in ((e.a, s1, R[0]), (e.b, s2, R[2])):
            if end in zi:
                G[zi[end], s] += 1 / r
                G[s, zi[end]] += 1 / r
            else:
                Gb[s, bi[end]] += 1 / r
        G[s1, s2] += 1 / R[1]
        G[s2, s1] += 1 / R[1]
    L = G - np.diag(G.sum(axis=1) + Gb.sum(axis=1))
    A = L / cap[:, None]
    Bt = Gb / cap[:, None]
    if ms is not None:
        A[np.arange(nz), np.arange(nz)] -= np.asarray(ms, dtype=float) * cp / cap[:nz]
    return A, Bt, cap


@pytest.fixture(scope="session")
def reference_linear_system():
    """``f(net, rbar_v, c_v, ms=None) -> (A, Bt, cap)`` built by hand (see its docstring)."""
    return _reference_linear_system


@pytest.fixture
def docs_snippets(tmp_path, monkeypatch):
    """``run(page)``: the ```python blocks of ``docs/<page>`` run in order, in one namespace,
    in ``tmp_path``; returns the namespace."""
    import re

    def run(page):
        text = (Path(__file__).resolve().parents[1] / "docs" / page).read_text()
        blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
        assert blocks, f"docs/{page} has no python snippet"
        monkeypatch.chdir(tmp_path)
        ns: dict = {}
        for code in blocks:
            exec(compile(code, f"docs/{page}", "exec"), ns)
        return ns
    return run


@pytest.fixture
def identify_split(tmp_path, monkeypatch):
    """``split(*args)``: the ``split`` options ``thermctl identify`` builds from these
    command-line arguments on a 4-day testbed (identify itself replaced by a stand-in that
    keeps its options)."""
    import warnings

    from typer.testing import CliRunner

    import thermctl.identify as ident_mod
    from thermctl.cli import app
    from thermctl.testbed import generate
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        generate(days=4, seed=0).write(tmp_path)
    seen = {}

    def stand_in(meas, opt, progress=None):
        seen["split"] = opt.split
        raise RuntimeError("stand-in: options seen")

    monkeypatch.setattr(ident_mod, "identify", stand_in)

    def split(*args):
        seen.clear()
        res = CliRunner().invoke(app, ["identify", str(tmp_path / "data.csv"), "-b",
                                       str(tmp_path / "building.yaml"), "-o",
                                       str(tmp_path / "out"), *args])
        assert "split" in seen, res.output
        return seen["split"]
    return split
