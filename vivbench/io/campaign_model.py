"""Campaign-model files: the fitted model (``save``/``load``) and its regimes ``campaign.regimes.nc``.

Two schemas, one owner:

- the *campaign model file* (format ``"vivbench-campaign-model"``, version
  :data:`CAMPAIGN_MODEL_VERSION`): everything a fitted
  :class:`vivbench.models.PooledSINDy` needs to predict, simulate, draw its
  curves and label windows. Written by :func:`write_campaign_model`, read and
  checked by :func:`read_campaign_model`; ``vivbench pool`` saves it as
  :data:`MODEL_NAME` (``campaign.model.nc``) beside the regimes file.
- the *campaign regimes* ``campaign.regimes.nc`` of ``vivbench pool`` (format
  ``"vivbench-campaign-regimes"``): every window's regime and verdict by the
  campaign model, its curves and, for ``PooledSINDy``, its coefficients.
  Written by :func:`write_campaign_regimes`, read by
  :func:`read_campaign_regimes`. Its ``model`` attribute names the campaign
  model (:data:`CAMPAIGN_MODEL_CLASSES`; absent in files of the pooled model written
  before it existed): only ``"PooledSINDy"`` files hold
  the 69 library coefficients (``coef``, ``coef_bootstrap``); a
  ``"VaryingCoefficientSINDy"`` file holds the windows' verdicts, the curves and
  per-equation spline settings, and its model lives in ``campaign.model.nc``
  (that model's own file, :meth:`vivbench.models.VaryingCoefficientSINDy.save`).
  A user's campaign model of the protocol adds the attribute ``model_class``
  (``"module:Class"``), whose ``load`` reads its ``campaign.model.nc``.

Earlier versions wrote the regimes as ``campaign.pooled.nc`` (format
``"vivbench-pooled"``, the model's settings in the attribute
``pooled_config_json``); :func:`regimes_file` finds such a file and
:func:`read_campaign_regimes` reads it as a current one.
"""

from __future__ import annotations

from pathlib import Path

import xarray as xr

from vivbench.io.model_file import ModelFileError, read_model_dataset
from vivbench.io.netcdf import write_netcdf_atomic

__all__ = [
    "REGIMES_NAME", "LEGACY_REGIMES_NAME", "MODEL_NAME", "REGIMES_FORMAT", "LEGACY_REGIMES_FORMAT",
    "CAMPAIGN_MODEL_FORMAT", "CAMPAIGN_MODEL_VERSION", "regimes_file", "write_campaign_regimes",
    "read_campaign_regimes", "write_campaign_model", "read_campaign_model", "CAMPAIGN_MODEL_CLASSES", "regimes_model_name",
]

#: File name of the campaign model's regimes (every window's regime and verdict, the curves).
REGIMES_NAME = "campaign.regimes.nc"
#: The name earlier versions gave that file; still read.
LEGACY_REGIMES_NAME = "campaign.pooled.nc"
#: File name of the fitted campaign model that ``vivbench pool`` saves beside :data:`REGIMES_NAME`.
MODEL_NAME = "campaign.model.nc"
REGIMES_FORMAT = "vivbench-campaign-regimes"
#: The ``format`` attribute earlier versions wrote in that file; still read.
LEGACY_REGIMES_FORMAT = "vivbench-pooled"
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

#: Campaign models a regimes file can come from (its ``model`` attribute; absent means the first).
CAMPAIGN_MODEL_CLASSES = ("PooledSINDy", "VaryingCoefficientSINDy")

#: Variables of a regimes file of the pooled model beyond :data:`_POOLED_VARIABLES`.
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


def regimes_file(directory) -> Path:
    """The campaign regimes file of a results directory.

    Parameters
    ----------
    directory : str or Path

    Returns
    -------
    Path
        ``directory/campaign.regimes.nc``; ``directory/campaign.pooled.nc``
        instead when only that file (written by an earlier version) is there.
        The path need not exist.
    """
    directory = Path(directory)
    current, legacy = directory / REGIMES_NAME, directory / LEGACY_REGIMES_NAME
    return legacy if legacy.is_file() and not current.is_file() else current


def write_campaign_regimes(ds, out_dir) -> Path:
    """Write the campaign regimes atomically as ``out_dir/campaign.regimes.nc``.

    A ``campaign.pooled.nc`` of an earlier version in ``out_dir`` is removed
    afterwards, so that the directory holds one regimes file.
    """
    path = Path(write_netcdf_atomic(ds, Path(out_dir) / REGIMES_NAME))
    (Path(out_dir) / LEGACY_REGIMES_NAME).unlink(missing_ok=True)
    return path


def read_campaign_regimes(path) -> xr.Dataset:
    """Load and check a campaign regimes file (``campaign.regimes.nc``, or ``campaign.pooled.nc`` of earlier versions).

    Parameters
    ----------
    path : str or Path
        The file (:func:`regimes_file` finds it in a directory).

    Returns
    -------
    xarray.Dataset
        Loaded; a file of an earlier version comes back as a current one:
        ``format`` is ``"vivbench-campaign-regimes"`` and the model's settings
        are in the attribute ``model_config_json`` (earlier:
        ``pooled_config_json``).

    Raises
    ------
    ModelFileError
        One line naming the file (missing, unreadable, other format, lacking a variable).
    """
    ds = read_model_dataset(path, fmt=(REGIMES_FORMAT, LEGACY_REGIMES_FORMAT), max_version=1,
                            variables=_POOLED_VARIABLES, what="campaign regimes")
    if "model_config_json" not in ds.attrs and "pooled_config_json" in ds.attrs:
        ds.attrs["model_config_json"] = ds.attrs.pop("pooled_config_json")
    ds.attrs["format"] = REGIMES_FORMAT
    name = ds.attrs.get("model", CAMPAIGN_MODEL_CLASSES[0])
    if name not in CAMPAIGN_MODEL_CLASSES and not ds.attrs.get("model_class"):
        # A user's model of the protocol names its class ("module:Class", attribute model_class).
        raise ModelFileError(f"{path}: campaign regimes of an unknown campaign model {name!r} "
                             f"(known: {', '.join(CAMPAIGN_MODEL_CLASSES)})")
    if name == "PooledSINDy":
        missing = [v for v in _POOLED_SINDY_VARIABLES if v not in ds.variables]
        if missing:
            raise ModelFileError(f"{path}: campaign regimes of PooledSINDy lack {', '.join(missing)}")
        _check_library(ds, path)
    return ds


def regimes_model_name(ds: xr.Dataset) -> str:
    """The campaign model a regimes file comes from: its ``model`` attribute, ``"PooledSINDy"`` when absent."""
    return str(ds.attrs.get("model", CAMPAIGN_MODEL_CLASSES[0]))


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
