"""The chain a twin repeats: identification and campaign model with a field run's own settings, and its scores.

A field run leaves its settings in its outputs: every identification result carries its
:class:`~vivbench.analysis.identify.IdentifyConfig` (``identify_config_json``), and the campaign
regimes file of ``vivbench pool`` the campaign model's parameters (``pooled_config_json``), the
held-out selection's evidence (``selection_json``: its candidates' options, folds, criterion and
perturbations) and the wind smoothing. :func:`identify_config_from_json` and :func:`pool_method`
rebuild them; :func:`run_chain` runs them on a synthetic campaign and :func:`chain_scores`
scores the fitted campaign model against the campaign's truth with
:func:`vivbench.validate.score_fitted`.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any, Sequence

import xarray as xr

from vivbench.analysis.identify import IdentifyConfig, identify_files
from vivbench.analysis.selection import SINGLE_SECTION_SHARE, varying_selection
from vivbench.core.errors import InputError
from vivbench.core.regime import DEFAULT_TAU
from vivbench.io.campaign_model import regimes_file
from vivbench.models.campaign_files import load_campaign_model
from vivbench.preprocess.config import PreprocessConfig
from vivbench.preprocess.derivative import Derivative
from vivbench.preprocess.wind_smoothing import smooth_wind
from vivbench.validate.methods import fit_method, score_fitted, scoring_inputs

__all__ = ["TWIN_METRICS", "PoolSettings", "identify_config_from_json", "pool_settings", "pool_method", "run_chain",
           "chain_scores"]

#: The recovery figures a twin predicts (keys of :func:`chain_scores`).
TWIN_METRICS = ("coverage", "flagged_right_share", "n_flagged", "rhs_error_true_AU_energy", "rhs_error_true_AU_median",
                "curve_error_linear", "curve_error_total", "curve_error_energy")


def identify_config_from_json(text: str) -> IdentifyConfig:
    """The :class:`IdentifyConfig` of a result's ``identify_config_json``."""
    try:
        data = json.loads(text)
        pre = {k: tuple(v) if isinstance(v, list) else v for k, v in data.pop("preprocess").items()}
        der = data.pop("derivative")
        data["thresholds"] = tuple(data["thresholds"])
        return IdentifyConfig(preprocess=PreprocessConfig(**pre), derivative=Derivative(**der), **data)
    except (json.JSONDecodeError, KeyError, TypeError, AttributeError) as exc:
        raise InputError(f"the results' identify_config_json cannot be read back ({type(exc).__name__}: {exc})") from None


@dataclasses.dataclass(frozen=True, kw_only=True)
class PoolSettings:
    """How ``vivbench pool`` fitted the field campaign's model, as recorded in its outputs.

    Attributes
    ----------
    selection : dict or None; the held-out selection (``options`` grid, ``n_folds``, ``criterion``,
        ``n_perturbations``, ``perturbation_timescale_s``, ``null``), None without one
    params : the campaign model's parameters: with a selection, its varying candidates' (the pooled one's where it
        had none; files of earlier versions: the chosen model's ``model_config_json``), else ``get_params()``
    model_path : the campaign model's directory or file (for a model without a selection)
    wind_smoothing_s : s; the smoothing ``pool`` applied to the records itself (0 when the model smooths)
    """

    selection: dict | None
    params: dict
    model_path: str
    wind_smoothing_s: float

    def to_dict(self) -> dict[str, Any]:
        return {"selection": self.selection, "params": self.params, "wind_smoothing_s": self.wind_smoothing_s}


def pool_settings(model_dir) -> PoolSettings:
    """Read the settings of ``vivbench pool`` from its output directory (or model file's directory).

    A selection recorded in ``selection_json`` is rebuilt with :func:`varying_selection` over the
    same options; otherwise the saved model is refitted with its own parameters (scikit-learn's
    ``get_params``), with the records' wind smoothed as ``pool`` did (``wind_smoothing_s``).
    """
    model_dir = Path(model_dir)
    directory = model_dir if model_dir.is_dir() else model_dir.parent
    path = regimes_file(directory)
    if not path.is_file():
        raise InputError(f"{directory}: no campaign regimes file of vivbench pool (campaign.regimes.nc); run vivbench pool")
    with xr.open_dataset(path) as ds:
        attrs = dict(ds.attrs)
    # the chosen model's parameters (files of earlier versions: pooled_config_json)
    params = json.loads(attrs.get("model_config_json") or attrs.get("pooled_config_json") or "{}")
    evidence = json.loads(attrs["selection_json"]) if attrs.get("selection_json") else None
    if evidence is not None:
        cands = evidence["candidates"]
        # files of earlier versions: varying candidates alone, without their parameters
        kinds = [(c.get("options") or {}).get("model_class", "varying") for c in cands]
        classes = list(dict.fromkeys(kinds))
        options: dict[str, list] = {}
        for cand, kind in zip(cands, kinds):
            if kind != "varying":  # the pooled candidates follow the varying ones' options and parameters
                continue
            for k, v in (cand.get("options") or {}).items():
                if k != "model_class" and v not in options.setdefault(k, []):
                    options[k].append(v)
        # the varying models' parameters whichever class was chosen (the pooled one's where there was none);
        # pool_method leaves out those among the options
        source = next((c for c, kind in zip(cands, kinds) if kind == "varying"), cands[0] if cands else {})
        params = dict(source["params"]) if "params" in source else params
        chosen = evidence.get("wind_smoothing") or {}
        if len(chosen.get("candidates_s", [])) > 1:  # chosen on the campaign (the model file holds it pinned)
            params = {**params, "wind_smoothing_s": chosen["prior_s"], "wind_smoothing_grid": chosen["candidates_s"]}
        selection = {"options": options, "model_classes": classes, "n_folds": int(evidence["n_folds"]),
                     "criterion": evidence["criterion"],
                     "n_perturbations": int(evidence["n_perturbations"]),
                     "perturbation_timescale_s": float(evidence["perturbation_timescale_s"]),
                     "single_section_share": float(evidence.get("single_section_share", SINGLE_SECTION_SHARE)),
                     # files written before the key was recorded had no such restriction
                     "min_time_constants": evidence.get("min_time_constants"),
                     # files written before the rank test was recorded had the one-standard-error rule alone
                     "rank_level": evidence.get("rank_level"),
                     # and without the test by wind
                     "wind_bins": evidence.get("wind_bins"),
                     "null": evidence.get("null") is not None}
        return PoolSettings(selection=selection, params=params, model_path=str(directory), wind_smoothing_s=0.0)
    model = load_campaign_model(directory)
    get = getattr(model, "get_params", None)
    if not callable(get):
        raise InputError(f"{directory}: the campaign model has no get_params(): the twin cannot refit it")
    smoothing = float(attrs.get("wind_smoothing_s", 0.0))
    return PoolSettings(selection=None, params=json.loads(json.dumps(get(), default=str)), model_path=str(directory),
                        wind_smoothing_s=0.0 if callable(getattr(model, "measured_wind", None)) else smoothing)


def pool_method(settings: PoolSettings, *, workers: int = 1):
    """An unfitted campaign model with the field run's settings (:func:`pool_settings`)."""
    if settings.selection is not None:
        sel = settings.selection
        fixed = {k: (tuple(v) if isinstance(v, list) else v) for k, v in settings.params.items()
                 if k not in sel["options"] and k not in ("n_folds", "seed")}
        return varying_selection(options={k: tuple(v) for k, v in sel["options"].items()}, n_folds=sel["n_folds"],
                                 criterion=sel["criterion"], n_perturbations=sel["n_perturbations"],
                                 perturbation_timescale_s=sel["perturbation_timescale_s"],
                                 single_section_share=sel.get("single_section_share", SINGLE_SECTION_SHARE),
                                 min_time_constants=sel.get("min_time_constants"), rank_level=sel.get("rank_level"),
                                 wind_bins=sel.get("wind_bins"), model_classes=tuple(sel.get("model_classes", ("varying",))),
                                 seed=int(settings.params.get("seed", 0)), workers=workers, null=sel["null"], **fixed)
    model = load_campaign_model(settings.model_path)
    return type(model)(**model.get_params())


def run_chain(event_files: Sequence, work_dir, identify: IdentifyConfig, method, *, wind_smoothing_s: float = 0.0):
    """Identify a synthetic campaign and fit the campaign model on it.

    Returns
    -------
    fitted, records, truths, windows
        The fitted model and :func:`scoring_inputs` (dA/dt of the campaign model, as ``pool`` takes it).
    """
    written, failures = identify_files(list(event_files), Path(work_dir), identify, workers=1)
    if not written:
        raise InputError(f"no event could be identified ({next(iter(failures.values()), 'nothing to identify')})")
    results = sorted(written, key=lambda p: p.name)
    identified = {p.name.removesuffix(".identify.nc") for p in results}
    events = sorted((Path(f) for f in event_files if Path(f).stem in identified), key=lambda p: p.name)
    records, truths, windows = scoring_inputs(events, results)
    if wind_smoothing_s > 0:
        records = [smooth_wind(r, wind_smoothing_s) for r in records]
    fitted, _ = fit_method(method, records)
    return fitted, records, truths, windows


def chain_scores(fitted, records, truths, windows, *, tau: float = DEFAULT_TAU) -> dict[str, float]:
    """:data:`TWIN_METRICS` of a fitted campaign model against the truth (``flagged_right_share`` is
    ``accuracy_identifiable``: the share of flagged window-equations whose regime is right)."""
    s = score_fitted(fitted, records, truths, windows=windows, tau=tau, simulate=False)
    n_flagged = 0 if math.isnan(s["coverage"]) else int(round(s["coverage"] * s["n_scored"]))
    out = {k: float(s[k]) for k in TWIN_METRICS if k in s}
    out.update(flagged_right_share=float(s["accuracy_identifiable"]), n_flagged=n_flagged)
    return {k: out[k] for k in TWIN_METRICS}
