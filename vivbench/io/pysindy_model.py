"""Files of the pysindy campaign and window models (format ``"vivbench-pysindy-model"``): what they need to predict.

Written by the ``save`` of :class:`vivbench.models.PySINDyCampaign`, :class:`~vivbench.models.PySINDyWindows`,
:class:`~vivbench.models.PySINDyCP` and the variants of :mod:`vivbench.models.pysindy_variants`; read by
:func:`read_pysindy_model` (their ``load``). A fitted ``pysindy.SINDy`` is not stored: the file holds its
coefficients, the names of its library's terms and the library's settings, from which ``load`` rebuilds the
library (and checks that it gives the stored terms), so that the loaded model predicts exactly as the saved one.

Variables: ``coef`` ((window,) equation, term) on the scaled variables, ``amplitude_ratios`` (equation,
section) for campaign models, ``coef_draws`` (draw, equation, term) for models with draws, ``window_start``,
``window_end`` (s) and ``window_event`` (window) for window models. Coordinate ``term``: the library's feature
names. Attributes: ``model`` (the class name), ``params_json`` (the constructor's parameters but ``sindy``),
``sindy_json`` (the settings of a user's ``sindy``: library and optimiser classes and their parameters, or
``"null"``), the scales ``a_scale`` (m), ``u_center``, ``u_scale`` (m/s), ``n_sections``, and the
class's own fitted scalars (:data:`PYSINDY_SCALARS`); ``events`` (JSON list) for window models.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from vivbench.io.model_file import ModelFileError, read_model_dataset
from vivbench.io.netcdf import write_netcdf_atomic

__all__ = ["PYSINDY_MODEL_FORMAT", "PYSINDY_MODEL_VERSION", "PYSINDY_SCALARS", "pysindy_model_dataset",
           "write_pysindy_model", "read_pysindy_model"]

PYSINDY_MODEL_FORMAT = "vivbench-pysindy-model"
PYSINDY_MODEL_VERSION = 1

#: Fitted scalars written as attributes when the model has them (name of the attribute: fitted attribute, type).
PYSINDY_SCALARS = {"a_scale": ("a_scale_", float), "u_center": ("u_center_", float), "u_scale": ("u_scale_", float),
                   "n_sections": ("n_sections_", int), "n_trajectories": ("n_trajectories_", int),
                   "other_share": ("other_share_", float), "thinning": ("thinning_", int),
                   "n_test_functions": ("n_test_functions_", int)}
#: Fitted arrays written when the model has them (fitted attribute: dimensions).
_ARRAYS = {"coef_draws_": ("draw", "equation", "term"), "amplitude_ratios_": ("equation", "section"),
           "window_start_": ("window",), "window_end_": ("window",), "window_event_": ("window",)}


def pysindy_model_dataset(model_name: str, fitted: Mapping[str, object], *, params_json: str,
                          sindy_json: str) -> xr.Dataset:
    """The file's dataset from a fitted pysindy model's attributes.

    Parameters
    ----------
    model_name : str
        The model's class name (attribute ``model``).
    fitted : mapping
        The fitted attributes by name (``vars(model)``): ``coef_`` (S, p) or (W, S, p), ``feature_names_``,
        the scalars of :data:`PYSINDY_SCALARS` it has, the arrays it has among ``coef_draws_``,
        ``amplitude_ratios_``, ``window_start_``, ``window_end_``, ``window_event_``, and ``event_ids_`` for
        window models.
    params_json, sindy_json : str
        The constructor's parameters but ``sindy``, and the settings of ``sindy`` (``"null"`` for none), as JSON.

    Returns
    -------
    xarray.Dataset, with the ``format`` and ``format_version`` attributes
    """
    coef = np.asarray(fitted["coef_"], dtype=float)
    dims = ("window", "equation", "term") if coef.ndim == 3 else ("equation", "term")
    data = {"coef": (dims, coef)}
    for name, array_dims in _ARRAYS.items():
        if fitted.get(name) is not None:
            kind = int if name == "window_event_" else float
            data[name.rstrip("_")] = (array_dims, np.asarray(fitted[name]).astype(kind))
    attrs = {"model": model_name, "params_json": params_json, "sindy_json": sindy_json}
    for attr, (name, kind) in PYSINDY_SCALARS.items():
        if fitted.get(name) is not None:
            attrs[attr] = kind(fitted[name])
    if fitted.get("event_ids_") is not None:
        attrs["events"] = json.dumps(list(fitted["event_ids_"]))
    attrs.update(format=PYSINDY_MODEL_FORMAT, format_version=PYSINDY_MODEL_VERSION)
    return xr.Dataset(data, coords={"term": [str(n) for n in fitted["feature_names_"]]}, attrs=attrs)


def write_pysindy_model(ds: xr.Dataset, path) -> Path:
    """Write a pysindy-model dataset (:func:`pysindy_model_dataset`, which carries the format) atomically."""
    if ds.attrs.get("format") != PYSINDY_MODEL_FORMAT:
        raise ValueError(f"not a pysindy-model dataset (format attribute {ds.attrs.get('format')!r})")
    return Path(write_netcdf_atomic(ds, Path(path)))


def read_pysindy_model(path, *, model_name: str) -> tuple[dict, object, dict]:
    """The constructor's parameters, the ``sindy`` settings and the fitted attributes of a pysindy-model file.

    Parameters
    ----------
    path : str or Path
    model_name : str
        The class the file must hold (its ``model`` attribute).

    Returns
    -------
    params : dict
        Keyword arguments of the model's constructor, but ``sindy``.
    sindy : dict or None
        The settings written for a user's ``sindy`` (None: the model's default or its own).
    fitted : dict
        The fitted attributes by name (``coef_``, ``feature_names_``, the scalars and arrays the file holds).

    Raises
    ------
    ModelFileError
        One line naming the file: missing, unreadable, of another format, version or model, lacking a part.
    """
    ds = read_model_dataset(path, fmt=PYSINDY_MODEL_FORMAT, max_version=PYSINDY_MODEL_VERSION, variables={},
                            what="pysindy model")
    if ds.attrs.get("model") != model_name:
        raise ModelFileError(f"{path}: a {ds.attrs.get('model')} file, not a {model_name} one")
    missing = [n for n in ("coef", "term") if n not in ds.variables]
    missing += [a for a in ("params_json", "sindy_json", "a_scale", "n_sections") if a not in ds.attrs]
    if missing:
        raise ModelFileError(f"{path}: pysindy model lacks {', '.join(missing)}")
    if ds["coef"].dims[-2:] != ("equation", "term"):
        raise ModelFileError(f"{path}: coef must end with the dimensions ('equation', 'term'); got {ds['coef'].dims}")
    fitted = {"coef_": np.asarray(ds["coef"].values, dtype=float),
              "feature_names_": [str(n) for n in ds["term"].values]}
    for name in _ARRAYS:
        if name.rstrip("_") in ds:
            fitted[name] = np.asarray(ds[name.rstrip("_")].values)
    if "window_event_" in fitted:
        fitted["window_event_"] = fitted["window_event_"].astype(int)
    for attr, (name, kind) in PYSINDY_SCALARS.items():
        if attr in ds.attrs:
            fitted[name] = kind(ds.attrs[attr])
    if "events" in ds.attrs:
        fitted["event_ids_"] = [str(e) for e in json.loads(ds.attrs["events"])]
    return json.loads(ds.attrs["params_json"]), json.loads(ds.attrs["sindy_json"]), fitted
