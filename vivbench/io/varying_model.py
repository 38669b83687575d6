"""The varying-coefficient model's file (format ``"vivbench-varying-model"``): its fitted arrays and settings.

Written by :meth:`vivbench.models.VaryingCoefficientSINDy.save` (``vivbench pool
--model varying`` saves it as ``campaign.model.nc``), read by
:func:`read_varying_model` (and :meth:`~vivbench.models.VaryingCoefficientSINDy.load`).
Variables: the spline coefficients ``coef`` (equation, basis, order), their
bootstrap replicates, knots, scales and the cross-validation's errors
(:data:`VARYING_ARRAYS`), the models of every order subset
(:data:`SUBSET_ARRAYS`), the fits at every candidate penalty
(:data:`PENALTY_ARRAYS`), with a yaw covariate its coefficients
(:data:`YAW_ARRAYS`, dimension ``yaw_power``), and ``wind_weights``. Attributes:
``model``, ``params_json`` (the constructor's parameters), the fitted choices
(``wind_smoothing_s_fitted``, ``penalty_choice_fitted``, ...), ``events``, and
``format`` / ``format_version`` (:data:`VARYING_MODEL_VERSION`).

Files written before the format was versioned (no ``format`` attribute) are
read as they were written: each generation of the file lacks what was added
after it, and :func:`read_varying_model` fills in what the model then did
(:data:`LEGACY_PARAMS`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.io.model_file import ModelFileError, read_model_dataset
from vivbench.io.netcdf import NETCDF_ENGINE, write_netcdf_atomic

__all__ = ["VARYING_MODEL_FORMAT", "VARYING_MODEL_VERSION", "VARYING_MODEL_NAME", "VARYING_ARRAYS", "SUBSET_ARRAYS",
           "PENALTY_ARRAYS", "YAW_ARRAYS", "LEGACY_PARAMS", "varying_model_dataset", "write_varying_model",
           "read_varying_model"]

VARYING_MODEL_FORMAT = "vivbench-varying-model"
#: Version written into new files; files without a ``format`` attribute are the unversioned generations.
VARYING_MODEL_VERSION = 1
#: The ``model`` attribute of the file.
VARYING_MODEL_NAME = "VaryingCoefficientSINDy"

#: Fitted arrays of every file (name of the attribute; the variable drops the trailing underscore) and their dims.
VARYING_ARRAYS = {"coef_": ("equation", "basis", "order"), "knots_": ("equation", "knot"),
                  "n_basis_": ("equation",), "penalty_": ("equation",), "orders_": ("equation", "order"),
                  "cv_error_": ("equation", "n_basis_candidate", "penalty_candidate"), "edf_": ("equation",),
                  "wind_range_": ("equation", "bound"), "y_scale_": ("equation",), "a_ref_": ("equation",),
                  "rss_": ("equation",), "coef_bootstrap_": ("bootstrap", "equation", "basis", "order")}
#: The confidence set of order subsets (absent from files written before it existed).
SUBSET_ARRAYS = {"subset_coef_": ("subset", "equation", "basis", "order"), "subset_loeo_": ("subset", "equation"),
                 "subset_plausible_": ("subset", "equation")}
#: The confidence set of penalties (absent from files written before it; the yaw coefficients only with a yaw
#: covariate).
PENALTY_ARRAYS = {"penalty_coef_": ("penalty_candidate", "equation", "basis", "order"),
                  "penalty_plausible_": ("penalty_candidate", "equation"),
                  "penalty_coef_yaw_": ("penalty_candidate", "equation", "basis", "order", "yaw_power")}
#: Written only with a yaw covariate (files of models without yaw stay as they were).
YAW_ARRAYS = {"coef_yaw_": ("equation", "basis", "order", "yaw_power"),
              "coef_yaw_bootstrap_": ("bootstrap", "equation", "basis", "order", "yaw_power"),
              "yaw_ref_": ("equation",), "yaw_fallback_": ("equation",), "yaw_min_": ("equation",),
              "yaw_max_": ("equation",), "subset_coef_yaw_": ("subset", "equation", "basis", "order", "yaw_power")}

#: Parameters absent from unversioned files and the value the model then had: before the yaw covariate, the
#: model's own wind smoothing (the wind was smoothed, or not, before the fit), its cross-validation, the
#: effective-variance weights, the signed-rank test, the weighted sections' winds and the least plausible penalty.
LEGACY_PARAMS = {"yaw_degree": 0, "wind_smoothing_s": 0.0, "wind_smoothing_grid": None, "eiv_weights": False,
                 "model_set_test": "z", "wind_weights": "equal", "penalty_choice": "cv",
                 "model_sets": True}


def _as_variable(name: str, value) -> np.ndarray:
    """The array written for a fitted attribute: int8 for the boolean ones, float otherwise."""
    kind = np.int8 if name in ("orders_", "subset_plausible_", "penalty_plausible_") else float
    return np.asarray(value).astype(kind)


def varying_model_dataset(fitted: Mapping[str, object], *, params_json: str, equations: Sequence[str]) -> xr.Dataset:
    """The file's dataset from a fitted model's attributes.

    Parameters
    ----------
    fitted : mapping
        The model's fitted attributes by name (``vars(model)``): every name of the tables above that the model
        has, and ``yaw_degree_``, ``wind_weights_``, ``n_samples_``, ``wind_smoothing_s_``,
        ``wind_smoothing_cv_``, ``penalty_cv_``, ``penalty_choice_``, ``wind_weights_choice_``, ``n_blocks_``,
        ``event_ids_``.
    params_json : str
        The constructor's parameters as JSON.
    equations : sequence of str
        The equations' names (coordinate ``equation``).

    Returns
    -------
    xarray.Dataset, with the ``format`` and ``format_version`` attributes
    """
    data = {name.rstrip("_"): (dims, _as_variable(name, fitted[name])) for name, dims in VARYING_ARRAYS.items()}
    data.update({name.rstrip("_"): (dims, _as_variable(name, fitted[name])) for name, dims in SUBSET_ARRAYS.items()})
    with_yaw = bool(fitted["yaw_degree_"])
    if with_yaw:
        data.update({name.rstrip("_"): (dims, np.asarray(fitted[name], dtype=float))
                     for name, dims in YAW_ARRAYS.items()})
    if fitted.get("penalty_coef_") is not None:
        data.update({name.rstrip("_"): (dims, _as_variable(name, fitted[name]))
                     for name, dims in PENALTY_ARRAYS.items() if with_yaw or "yaw" not in name})
    data["wind_weights"] = (("equation",), np.asarray(fitted["wind_weights_"], dtype=float))
    attrs = {"model": VARYING_MODEL_NAME, "params_json": params_json, "n_samples": fitted["n_samples_"],
             "wind_smoothing_s_fitted": float(fitted["wind_smoothing_s_"]),
             "wind_smoothing_cv": json.dumps([float(x) for x in fitted["wind_smoothing_cv_"]]),
             "penalty_cv": json.dumps([float(x) for x in fitted["penalty_cv_"]]),
             "penalty_choice_fitted": fitted["penalty_choice_"],
             "wind_weights_choice": fitted["wind_weights_choice_"],
             "n_blocks": fitted["n_blocks_"], "events": json.dumps(fitted["event_ids_"]),
             "format": VARYING_MODEL_FORMAT, "format_version": VARYING_MODEL_VERSION}
    return xr.Dataset(data, coords={"equation": list(equations), "order": np.arange(4)}, attrs=attrs)


def write_varying_model(ds: xr.Dataset, path) -> Path:
    """Write a varying-model dataset (:func:`varying_model_dataset`, which carries the format) atomically."""
    if ds.attrs.get("format") != VARYING_MODEL_FORMAT:
        raise ValueError(f"not a varying-model dataset (format attribute {ds.attrs.get('format')!r})")
    return write_netcdf_atomic(ds, path)


def _open(path) -> xr.Dataset:
    """The file's dataset: checked against the format when it carries one, as written when unversioned."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such varying-coefficient model file")
    try:
        with xr.open_dataset(path, engine=NETCDF_ENGINE) as ds:
            fmt, name = ds.attrs.get("format"), ds.attrs.get("model")
    except Exception as exc:  # noqa: BLE001 - any reader failure means "not such a file"
        raise ModelFileError(f"{path}: cannot be read as a NetCDF-4 varying-coefficient model "
                             f"({type(exc).__name__})") from exc
    if name != VARYING_MODEL_NAME:
        raise InputError(f"{path}: not a {VARYING_MODEL_NAME} file")
    if fmt is None:  # written before the format was versioned
        with xr.open_dataset(path, engine=NETCDF_ENGINE) as ds:
            return ds.load()
    return read_model_dataset(path, fmt=VARYING_MODEL_FORMAT, max_version=VARYING_MODEL_VERSION,
                              variables={name.rstrip("_"): dims for name, dims in VARYING_ARRAYS.items()},
                              what="varying-coefficient model")


def _params(ds: xr.Dataset) -> dict:
    """The constructor's parameters, with what unversioned files lack filled in (:data:`LEGACY_PARAMS`)."""
    params = json.loads(ds.attrs["params_json"])
    params["n_basis"], params["penalties"] = tuple(params["n_basis"]), tuple(params["penalties"])
    for key, value in LEGACY_PARAMS.items():
        params.setdefault(key, value)
    # Files written while "auto" chose by the campaign's size: the choice the fit made.
    if params["penalty_choice"] == "auto":
        params["penalty_choice"] = str(ds.attrs.get("penalty_choice_fitted", "cv"))
    if params["wind_weights"] == "auto":
        params["wind_weights"] = str(ds.attrs.get("wind_weights_choice", "equal"))
    if not isinstance(params["wind_weights"], str):
        params["wind_weights"] = tuple(params["wind_weights"])
    if params["wind_smoothing_grid"] is not None:
        params["wind_smoothing_grid"] = tuple(params["wind_smoothing_grid"])
    return params


def read_varying_model(path, *, n_subsets: int) -> tuple[dict, dict]:
    """The constructor's parameters and the fitted attributes of a varying-model file (any generation).

    Parameters
    ----------
    path : str or Path
    n_subsets : int
        Order subsets of the model's confidence set; files written before the set existed get the fitted
        model as their only plausible subset.

    Returns
    -------
    params : dict
        Keyword arguments of the model's constructor.
    fitted : dict
        The fitted attributes by name (``coef_``, ...).

    Raises
    ------
    InputError
        One line naming the file: missing, unreadable, of another model, format or version.
    """
    ds = _open(path)
    params = _params(ds)
    fit = {name: np.asarray(ds[name.rstrip("_")].values) for name in VARYING_ARRAYS}
    S, Mmax = fit["coef_"].shape[:2]
    J = int(ds.sizes["yaw_power"]) if "coef_yaw" in ds else 0
    fit["yaw_degree_"] = J
    if J:
        for name in YAW_ARRAYS:
            if name.rstrip("_") in ds:  # yaw_min, yaw_max: absent from files written before them (unknown: NaN)
                fit[name] = np.asarray(ds[name.rstrip("_")].values)
        for name in ("yaw_min_", "yaw_max_"):
            if name.rstrip("_") not in ds:
                fit[name] = np.full(S, np.nan)
    else:
        fit["coef_yaw_"] = np.zeros((S, Mmax, 4, 0))
        fit["coef_yaw_bootstrap_"] = np.zeros(fit["coef_bootstrap_"].shape + (0,))
        fit["yaw_ref_"], fit["yaw_fallback_"], fit["yaw_min_"] = np.ones(S), np.zeros(S), np.zeros(S)
        fit["yaw_max_"] = np.zeros(S)
        fit["subset_coef_yaw_"] = np.zeros((n_subsets, S, Mmax, 4, 0))
    if "subset_coef" in ds:
        for name in SUBSET_ARRAYS:
            fit[name] = np.asarray(ds[name.rstrip("_")].values)
        fit["subset_plausible_"] = fit["subset_plausible_"].astype(bool)
    else:  # older files: the fitted model alone is its confidence set
        fit["subset_coef_"] = np.broadcast_to(fit["coef_"], (n_subsets,) + fit["coef_"].shape).copy()
        fit["subset_coef_yaw_"] = np.broadcast_to(fit["coef_yaw_"], (n_subsets,) + fit["coef_yaw_"].shape).copy()
        fit["subset_loeo_"] = np.full((n_subsets, S), np.nan)
        fit["subset_plausible_"] = np.zeros((n_subsets, S), dtype=bool)
        fit["subset_plausible_"][0] = True
    if "penalty_coef" in ds:
        fit["penalty_coef_"] = np.asarray(ds["penalty_coef"].values)
        fit["penalty_plausible_"] = np.asarray(ds["penalty_plausible"].values).astype(bool)
        fit["penalty_coef_yaw_"] = (np.asarray(ds["penalty_coef_yaw"].values) if J
                                    else np.zeros(fit["penalty_coef_"].shape + (0,)))
    else:  # older files: the fitted penalty alone is its set
        fit["penalty_coef_"] = fit["penalty_coef_yaw_"] = fit["penalty_plausible_"] = None
    fit["n_basis_"] = fit["n_basis_"].astype(int)
    fit["orders_"] = fit["orders_"].astype(bool)
    fit["n_samples_"], fit["n_blocks_"] = int(ds.attrs["n_samples"]), int(ds.attrs["n_blocks"])
    fit["n_sections_"] = S = int(ds.sizes["equation"])
    fit["wind_weights_"] = (np.asarray(ds["wind_weights"].values, dtype=float) if "wind_weights" in ds
                            else np.full(S, 1.0 / S))
    fit["event_ids_"] = json.loads(ds.attrs["events"])
    fit["wind_smoothing_s_"] = float(ds.attrs.get("wind_smoothing_s_fitted", params["wind_smoothing_s"]))
    fit["wind_smoothing_cv_"] = np.asarray(json.loads(ds.attrs.get("wind_smoothing_cv", "[NaN]")), dtype=float)
    # files written before the least plausible penalty: the fitted penalty was the cross-validated one
    fit["penalty_cv_"] = (np.asarray(json.loads(ds.attrs["penalty_cv"]), dtype=float) if "penalty_cv" in ds.attrs
                          else fit["penalty_"].astype(float).copy())
    fit["penalty_choice_"] = str(ds.attrs.get("penalty_choice_fitted", params["penalty_choice"]))
    fit["wind_weights_choice_"] = str(ds.attrs.get("wind_weights_choice", params["wind_weights"]
                                                   if isinstance(params["wind_weights"], str) else "given"))
    return params, fit
