"""Campaign-model files: the fitted model (``save``/``load``) and the pooled result ``campaign.pooled.nc``.

Two schemas, one owner:

- the *campaign model file* (format ``"vivbench-campaign-model"``, version
  :data:`CAMPAIGN_MODEL_VERSION`): everything a fitted
  :class:`vivbench.models.PooledSINDy` needs to predict, simulate, draw its
  curves and label windows. Written by :func:`write_campaign_model`, read and
  checked by :func:`read_campaign_model`; ``vivbench pool`` saves it as
  :data:`MODEL_NAME` (``campaign.model.nc``) beside the pooled result.
- the *pooled result* ``campaign.pooled.nc`` of ``vivbench pool`` (format
  ``"vivbench-pooled"``): the model's coefficients with every window's regime.
  Written by :func:`write_pooled`, read by :func:`read_pooled`. Its ``model``
  attribute names the campaign model (:data:`POOLED_MODELS`; absent in files of
  the SINDy model written before it existed): only ``"PooledSINDy"`` files hold
  the 69 library coefficients (``coef``, ``coef_bootstrap``); a
  ``"VaryingCoefficientSINDy"`` file holds the windows' verdicts, the curves and
  per-equation spline settings, and its model lives in ``campaign.model.nc``
  (that model's own file, :meth:`vivbench.models.VaryingCoefficientSINDy.save`).
"""

from __future__ import annotations

from pathlib import Path

import xarray as xr

from vivbench.io.model_file import ModelFileError, read_model_dataset
from vivbench.io.netcdf import write_netcdf_atomic

__all__ = [
    "POOLED_NAME", "MODEL_NAME", "POOLED_FORMAT", "CAMPAIGN_MODEL_FORMAT", "CAMPAIGN_MODEL_VERSION", "write_pooled",
    "read_pooled", "write_campaign_model", "read_campaign_model", "POOLED_MODELS", "pooled_model_name",
]

POOLED_NAME = "campaign.pooled.nc"
#: File name of the fitted campaign model that ``vivbench pool`` saves beside :data:`POOLED_NAME`.
MODEL_NAME = "campaign.model.nc"
POOLED_FORMAT = "vivbench-pooled"
CAMPAIGN_MODEL_FORMAT = "vivbench-campaign-model"
CAMPAIGN_MODEL_VERSION = 1

#: Variables of a campaign model file and their dimensions.
_MODEL_VARIABLES = {
    "coef": ("equation", "feature"),
    "coef_scaled": ("equation", "feature"),
    "coef_bootstrap": ("bootstrap", "equation", "feature"),
    "threshold": ("equation",),
    "n_terms": ("equation",),
    "rss": ("equation",),
    "aicc": ("equation",),
    "y_scale": ("equation",),
    "correlation_samples": ("equation",),
    "rss_scaled": ("equation",),
    "amplitude_ratios": ("equation", "section"),
    "gram_inv": ("basis", "basis_"),
    "to_physical": ("basis", "basis_"),
}

#: Campaign models a pooled result can come from (its ``model`` attribute; absent means the first).
POOLED_MODELS = ("PooledSINDy", "VaryingCoefficientSINDy")

#: Variables of a pooled result of the SINDy model beyond :data:`_POOLED_VARIABLES`.
_POOLED_SINDY_VARIABLES = {
    "coef": ("equation", "feature"),
    "coef_bootstrap": ("bootstrap", "equation", "feature"),
}

_POOLED_VARIABLES = {
    "regime": ("window_all", "equation"),
    "identifiable": ("window_all", "equation"),
    "order_rms": ("window_all", "equation", "order"),
    "window_start": ("window_all",),
    "window_end": ("window_all",),
    "event_id": ("window_all",),
}


def write_pooled(ds, out_dir) -> Path:
    """Write a pooled result atomically as ``out_dir/campaign.pooled.nc``."""
    return Path(write_netcdf_atomic(ds, Path(out_dir) / POOLED_NAME))


def read_pooled(path) -> xr.Dataset:
    """Load and check a pooled result (``campaign.pooled.nc``).

    Raises
    ------
    ModelFileError
        One line naming the file (missing, unreadable, other format, lacking a variable).
    """
    ds = read_model_dataset(path, fmt=POOLED_FORMAT, max_version=1, variables=_POOLED_VARIABLES, what="pooled result")
    name = ds.attrs.get("model", POOLED_MODELS[0])
    if name not in POOLED_MODELS:
        raise ModelFileError(f"{path}: pooled result of an unknown campaign model {name!r} (known: {', '.join(POOLED_MODELS)})")
    if name == "PooledSINDy":
        missing = [v for v in _POOLED_SINDY_VARIABLES if v not in ds.variables]
        if missing:
            raise ModelFileError(f"{path}: pooled result of PooledSINDy lacks {', '.join(missing)}")
        _check_library(ds, path)
    return ds


def pooled_model_name(ds: xr.Dataset) -> str:
    """The campaign model a pooled result comes from: its ``model`` attribute, ``"PooledSINDy"`` when absent."""
    return str(ds.attrs.get("model", POOLED_MODELS[0]))


def _check_library(ds: xr.Dataset, path) -> None:
    S, p = ds.sizes["equation"], ds.sizes["feature"]
    if S < 1 or p != 23 * S:
        raise ModelFileError(f"{path}: feature must have 23 x equation = {23 * S} entries; got {p}")


def write_campaign_model(ds: xr.Dataset, path) -> Path:
    """Check and write a campaign model file atomically.

    Parameters
    ----------
    ds : xarray.Dataset
        Built by :meth:`vivbench.models.PooledSINDy.to_dataset`: the variables of
        :data:`_MODEL_VARIABLES` and attributes ``params_json``, ``n_samples``,
        ``n_blocks``, ``enough_data``, ``cond``. ``format`` and
        ``format_version`` are set here.
    path : str or Path

    Returns
    -------
    Path
    """
    missing = [v for v in _MODEL_VARIABLES if v not in ds.variables]
    if missing:
        raise ValueError(f"a campaign model dataset needs {', '.join(missing)}")
    for name, dims in _MODEL_VARIABLES.items():
        if tuple(ds[name].dims) != dims:
            raise ValueError(f"campaign model variable {name} must have dimensions {dims}; got {ds[name].dims}")
    _check_library(ds, "campaign model dataset")
    ds = ds.copy()
    ds.attrs.update(format=CAMPAIGN_MODEL_FORMAT, format_version=CAMPAIGN_MODEL_VERSION)
    return Path(write_netcdf_atomic(ds, Path(path)))


def read_campaign_model(path) -> xr.Dataset:
    """Load and check a campaign model file written by :func:`write_campaign_model`.

    Raises
    ------
    ModelFileError
        One line naming the file: missing, unreadable, another format or a newer
        version, lacking a variable or attribute, or inconsistent shapes.
    """
    ds = read_model_dataset(path, fmt=CAMPAIGN_MODEL_FORMAT, max_version=CAMPAIGN_MODEL_VERSION,
                            variables=_MODEL_VARIABLES, what="campaign model")
    _check_library(ds, path)
    if ds.sizes["section"] != ds.sizes["equation"] or ds.sizes["basis"] != ds.sizes["feature"]:
        raise ModelFileError(f"{path}: section and basis sizes must match equation and feature")
    missing = [a for a in ("params_json", "n_samples", "n_blocks", "enough_data", "cond") if a not in ds.attrs]
    if missing:
        raise ModelFileError(f"{path}: campaign model lacks the attribute(s) {', '.join(missing)}")
    return ds
