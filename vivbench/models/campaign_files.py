"""The campaign model that ``vivbench pool`` left in a directory, loaded as a model of the protocol.

A built-in model's file names its class in its ``model`` attribute (``PooledSINDy`` when absent);
a user's model of the protocol is named by the ``model_class`` attribute (``"module:Class"``,
:func:`vivbench.models.model_class_path`) of its regimes file, and loaded by that class's ``load``.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import xarray as xr

from vivbench.core.errors import InputError
from vivbench.io.campaign_model import (LEGACY_REGIMES_FORMAT, MODEL_NAME, REGIMES_FORMAT, REGIMES_NAME,
                                        read_campaign_regimes, regimes_file, regimes_model_name)
from vivbench.io.model_file import ModelFileError
from vivbench.models.campaign import PooledSINDy
from vivbench.models.varying import VaryingCoefficientSINDy

__all__ = ["campaign_model_file", "load_campaign_model"]


def campaign_model_file(directory) -> Path | None:
    """The campaign model that ``vivbench pool`` left in a directory, if any.

    Parameters
    ----------
    directory : path of a results directory

    Returns
    -------
    Path or None
        ``campaign.model.nc`` when present, else ``campaign.regimes.nc`` (outputs
        written before the model file existed; :func:`load_campaign_model` then
        rebuilds the model from its ``coef``), else None.
    """
    for path in (Path(directory) / MODEL_NAME, regimes_file(directory)):
        if path.is_file():
            return path
    return None


def _file_model_name(path: Path) -> tuple[str | None, str | None]:
    """The ``model`` and ``format`` attributes of a NetCDF file (None when absent or unreadable)."""
    try:
        with xr.open_dataset(path) as ds:
            name, fmt = ds.attrs.get("model"), ds.attrs.get("format")
    except Exception:  # noqa: BLE001 - the readers below give the one-line error
        return None, None
    return (None if name is None else str(name)), (None if fmt is None else str(fmt))


def load_campaign_model(path):
    """The campaign model of ``vivbench pool`` as a model of the protocol (docs/methods.md).

    Parameters
    ----------
    path : path
        A campaign model file (``campaign.model.nc``: :meth:`PooledSINDy.save`
        or :meth:`VaryingCoefficientSINDy.save`, told apart by the file's
        ``model`` attribute), a campaign regimes file (``campaign.regimes.nc``) or a
        directory holding one of them (the model file first, see
        :func:`campaign_model_file`).

    Returns
    -------
    PooledSINDy or VaryingCoefficientSINDy
        A ``PooledSINDy`` file is loaded with :meth:`PooledSINDy.load`; from a
        regimes file (older outputs) rebuilt with :meth:`PooledSINDy.from_regimes`,
        which predicts, gives order contributions, simulates and prints
        equations but has no ``curves``. A file whose ``model`` attribute is
        ``"VaryingCoefficientSINDy"`` is loaded with
        :meth:`VaryingCoefficientSINDy.load`.

    Raises
    ------
    InputError
        One line naming the file or directory: nothing of ``vivbench pool``
        there, a file that is neither a campaign model nor a campaign regimes file, a
        regimes file of the varying model without its model file, or (for a
        directory) a model file of another model than the regimes file's.
    """
    path = Path(path)
    plugin = _plugin_class(path)
    if plugin is not None:
        return _load_plugin(plugin, path)
    pooled_name = None
    if path.is_dir():
        found = campaign_model_file(path)
        if found is None:
            raise InputError(f"{path}: no campaign model ({MODEL_NAME} or {REGIMES_NAME}) in this directory; "
                             "run vivbench pool first")
        if found.name == MODEL_NAME and regimes_file(path).is_file():
            pooled_name = _file_model_name(regimes_file(path))[0] or "PooledSINDy"
        path = found
    name, fmt = _file_model_name(path) if path.is_file() else (None, None)
    if pooled_name is not None and (name or "PooledSINDy") != pooled_name:
        raise InputError(f"{path}: a {name or 'PooledSINDy'} model beside a campaign regimes file of {pooled_name}; "
                         "re-run vivbench pool")
    if name == VaryingCoefficientSINDy.__name__:
        if fmt not in (REGIMES_FORMAT, LEGACY_REGIMES_FORMAT):
            return VaryingCoefficientSINDy.load(path)
        raise InputError(f"{path}: a campaign regimes file of VaryingCoefficientSINDy holds no model; its {MODEL_NAME} "
                         "is needed (re-run vivbench pool --model varying)")
    try:
        return PooledSINDy.load(path)
    except ModelFileError as exc:
        try:
            pooled = read_campaign_regimes(path)
        except ModelFileError:
            raise exc from None
    if regimes_model_name(pooled) != "PooledSINDy":
        raise InputError(f"{path}: a campaign regimes file of {regimes_model_name(pooled)} holds no model; its {MODEL_NAME} "
                         "is needed (re-run vivbench pool)")
    return PooledSINDy.from_regimes(pooled)


def _plugin_class(path: Path) -> str | None:
    """The ``model_class`` (``"module:Class"``, :func:`vivbench.models.model_class_path`) that ``vivbench pool``
    wrote for a model of the protocol other than the built-in ones: the file's own attribute, else the
    campaign regimes file's in the file's directory (or in the directory given)."""
    candidates = [regimes_file(path)] if path.is_dir() else [path, regimes_file(path.parent)]
    for candidate in candidates:
        if candidate.is_file():
            try:
                with xr.open_dataset(candidate) as ds:
                    value = ds.attrs.get("model_class")
            except Exception:  # noqa: BLE001 - the built-in readers give the one-line error
                continue
            if value:
                return str(value)
    return None


def _load_plugin(spec: str, path: Path):
    """``Class.load(model file)`` of the class ``spec`` (``"module:Qualified.Name"``) that pool's file names."""
    module_name, _, qualname = spec.partition(":")
    try:
        obj = importlib.import_module(module_name)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise InputError(f"{path}: the campaign model's class {spec!r} cannot be imported ({exc}); "
                         "is its module on PYTHONPATH?") from None
    model_path = path / MODEL_NAME if path.is_dir() else path
    if model_path.name == REGIMES_NAME:
        model_path = model_path.parent / MODEL_NAME
    if not model_path.is_file():
        raise InputError(f"{model_path}: no campaign model file of {spec} (re-run vivbench pool)")
    return obj.load(model_path)
