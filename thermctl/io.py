"""The model file ``model.json``: save and load an identified model exactly.

Layout (``format: thermctl-model``, ``version: 1``)::

    {
      "format": "thermctl-model", "version": 1, "thermctl": "0.1.0",
      "spec": {...},                      # the building spec, R/C form
      "convection": [{"a": .., "b": .., "d": .., "score": ..}, ...],
      "parameters": {"rbar_v": float | [per edge], "c_v": float | [per edge]},
      "alpha": 9.8696,
      "units": {"temperature": "degC", "rbar_v": "K/(W m)", "c_v": "J/K", ...},
      "meta": {...}                       # data range, fit diagnostics, metrics
    }

Floats are written with ``repr`` precision by the JSON encoder, so a load/save
round trip is exact.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from . import __version__
from .errors import ModelError, SpecError
from .model import ThermalModel
from .network import ThermalNetwork
from .spec import spec_from_dict

__all__ = ["save_model", "load_model", "model_to_dict", "model_from_dict", "atomic_write_text",
           "read_json_file"]

FORMAT = "thermctl-model"
VERSION = 1
UNITS = {"temperature": "degC", "rbar_v": "K/(W m)", "c_v": "J/K", "d": "m",
         "R": "K/W", "C": "J/K", "ms": "kg/s", "Q": "W", "time": "s"}


def _plain(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    return v


def model_to_dict(model: ThermalModel) -> dict:
    """The ``model.json`` content of a model, as plain data."""
    net = model.network
    scores = model.meta.get("edge_scores", {})
    conv = [{"a": e.a, "b": e.b, "d": e.d, **({"score": scores[e.name]} if e.name in scores else {})}
            for e in net.convection_edges]
    return {
        "format": FORMAT,
        "version": VERSION,
        "thermctl": __version__,
        "spec": net.spec.to_dict(),
        "convection": conv,
        "parameters": {"rbar_v": _plain(model.rbar_v), "c_v": _plain(model.c_v)},
        "alpha": net.spec.alpha() if net.spec.walls else None,
        "units": UNITS,
        "meta": json.loads(json.dumps(model.meta, default=_plain)),
    }


def model_from_dict(data: dict, source: str = "<dict>") -> ThermalModel:
    """Inverse of :func:`model_to_dict`."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ModelError(f"{source}: not a thermctl model file (missing 'format: {FORMAT}')")
    if data.get("version") != VERSION:
        raise ModelError(f"{source}: model file version {data.get('version')!r}, "
                         f"this thermctl reads version {VERSION}")
    try:
        spec = spec_from_dict(data["spec"], source=f"{source}:spec")
        conv = [(c["a"], c["b"], c["d"]) for c in data["convection"]]
        net = ThermalNetwork(spec, conv)
        par = data["parameters"]
        model = ThermalModel(net, rbar_v=par["rbar_v"], c_v=par["c_v"], meta=data.get("meta", {}))
        model.p  # validates the parameter shapes and values
    except KeyError as exc:
        raise ModelError(f"{source}: model file lacks the entry {exc}") from None
    except SpecError as exc:
        raise ModelError(f"{source}: invalid spec inside the model file: {exc}") from None
    return model


def atomic_write_text(path, text: str) -> None:
    """Write a file completely or not at all (temporary file + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file ordinary permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _existing_file(path, what: str, error: type[Exception]) -> Path:
    """``path`` as a :class:`~pathlib.Path`; ``error`` naming it and ``what`` if it is no file."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: {what} not found")
    return path


def read_json_file(path, what: str = "file", error: type[Exception] = ModelError):
    """The content of a JSON file, with errors that name the file.

    Parameters
    ----------
    path : str or Path
    what : str, optional
        What the file is, for the message when it is missing (e.g. ``"model file"``).
    error : type of Exception, optional
        Raised if the file is missing or not valid JSON (default :class:`ModelError`).

    Returns
    -------
    dict or list
        The decoded JSON.

    Examples
    --------
    >>> read_json_file("out/model.json", "model file")   # doctest: +SKIP
    """
    path = _existing_file(path, what, error)
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise error(f"{path}: not valid JSON: {exc}") from None


def save_model(model: ThermalModel, path) -> None:
    """Write ``model.json`` (atomically).

    Parameters
    ----------
    model : ThermalModel
    path : str or Path
    """
    atomic_write_text(path, json.dumps(model_to_dict(model), indent=2))


def load_model(path) -> ThermalModel:
    """Load a model saved by :func:`save_model`; the round trip is exact.

    Examples
    --------
    >>> model = load_model("out/model.json")       # doctest: +SKIP
    >>> sys = model.to_statespace(model.operating_point(ms=0.05, Ts=14, T=5))  # doctest: +SKIP
    """
    data = read_json_file(path, "model file")
    return model_from_dict(data, source=str(Path(path)))


def save_statespace(sys, path, op=None, info=None, kalman=None) -> None:
    """Save a ``control.StateSpace`` as ``.npz``: ``A, B, C, D, dt`` and the signal names.

    Load with `load_statespace`.

    Parameters
    ----------
    sys : control.StateSpace
    path : str or Path
    op : OperatingPoint, optional
        Stored as ``x_op``, ``u_op``: the linear model is in deviations from it.
    info : dict, optional
        Plain data stored as JSON in ``info`` (``thermctl export`` puts the operating point
        with the source of every value, and the disturbance inputs, there).
    kalman : dict, optional
        Arrays and name lists of the identified Kalman filter
        (``thermctl.export.KalmanFilter.arrays``), stored as ``kf_<name>``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = dict(A=sys.A, B=sys.B, C=sys.C, D=sys.D, dt=np.float64(sys.dt or 0.0),
                  states=np.array(sys.state_labels), inputs=np.array(sys.input_labels),
                  outputs=np.array(sys.output_labels), name=np.array(sys.name))
    if op is not None:
        arrays.update(x_op=np.asarray(op.x), u_op=np.asarray(op.u))
    if info is not None:
        arrays["info"] = np.array(json.dumps(info, default=_plain))
    for k, v in (kalman or {}).items():
        arrays[f"kf_{k}"] = np.asarray(v)
    tmp = path.with_name(f".{path.name}.tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def load_statespace(path):
    """Load a ``control.StateSpace`` saved by :func:`save_statespace` (names included).

    Returns
    -------
    sys : control.StateSpace
    extras : dict
        ``x_op``/``u_op`` arrays, ``info`` (dict: operating point with the source of each
        value, disturbance inputs) and ``kalman`` (dict of the Kalman filter's arrays:
        ``A, B, C, Qc, R``, at a sample time also ``Phi, Gamma, Qd, P, K``; name lists
        ``states, inputs, outputs``) — each only if the file has it.

    Examples
    --------
    >>> sys, extras = load_statespace("ss.npz")                      # doctest: +SKIP
    >>> extras["info"]["operating_point"]["inputs"]["ms"]          # doctest: +SKIP
    """
    import control as ct

    path = _existing_file(path, "state-space file", ModelError)
    with np.load(path, allow_pickle=False) as f:
        dt = float(f["dt"])
        sys = ct.ss(f["A"], f["B"], f["C"], f["D"], dt=dt if dt > 0 else 0,
                    states=[str(s) for s in f["states"]], inputs=[str(s) for s in f["inputs"]],
                    outputs=[str(s) for s in f["outputs"]], name=str(f["name"]))
        extras = {k: f[k] for k in ("x_op", "u_op") if k in f}
        if "info" in f:
            extras["info"] = json.loads(str(f["info"]))
        kf = {}
        for k in f.files:
            if k.startswith("kf_"):
                v = f[k]
                kf[k[3:]] = [str(s) for s in v] if v.dtype.kind == "U" else \
                    (float(v) if v.ndim == 0 else v)
        if kf:
            extras["kalman"] = kf
    return sys, extras
