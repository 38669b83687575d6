"""Method comparison: the identification chain scored on synthetic campaigns over a grid of variants.

A grid (TOML, :func:`load_compare_config`) names levels of ten factors:

====================== ============================================= ==========================
factor                 meaning                                        default (base) level
====================== ============================================= ==========================
derivative             dA/dt method: tv, savgol, spline,             tv
                       finite_difference
scaling                library basis: scaled (centred and scaled U),  scaled
                       raw (physical monomials), normalized
optimizer              stlsq (fast engine), sr3, ensemble             stlsq
window                 window length, s (step = ``step_ratio`` x it)  50
accel_noise            accelerometer noise floor as a multiple of     1
                       the default 30 micro-g/sqrt(Hz)
anemometer_noise       anemometer relative rms error                  0.01
turbulence_intensity   sigma_u / U of the turbulence field            0.08
aero                   realism: aerodynamic functions (docs/concepts.md (no inverse crime)):   in_library
                       in_library (polynomials in U) or realistic
                       (functions of reduced velocity, yaw factor)
felt_wind              realism: the wind the deck feels: anemometer   anemometer
                       (its own low-passed wind) or tributary (the
                       average over each section's tributary length)
drift                  realism: relative amplitude of the daily       0
                       damping drift (ChangesConfig.drift_amplitude),
                       in [0, 1)
====================== ============================================= ==========================

``method`` (docs/methods.md) names the method scored in the cell: ``"windows"`` (the
paper's window SINDy: the identification itself, the default), ``"pooled"``,
``"varying"``, ``"pysindy-cp"``, ``"binned"`` or ``"package.module:factory"`` (a factory
with no arguments returning any object with ``fit(records)``; see
:mod:`vivbench.validate.methods`). Every method of a cell is fitted to the
records of that cell's identification (its A, U and dA/dt, with the cell's
``derivative``; :func:`vivbench.analysis.records_from_results`) and scored on
the identification's windows by :func:`vivbench.validate.score_fitted`, the
same scores for built-in and plug-in methods: a method without an
identifiability verdict is scored on all windows, with coverage 0. The
"windows" rows are the identification's own window models, regimes and
verdicts (:meth:`vivbench.validate.FittedWindows.from_results`). A grid with
``method`` adds the columns ``method``, ``curve_error_linear``,
``curve_error_total``, ``curve_error_energy``, ``simulation_nmse``, ``simulation_covered`` and
``fit_time_s`` (the method's fit; for "windows" the identification's wall
time) to ``compare.csv``; grids without it give the table as before.

The three realism factors change the generator (the other settings of the
realistic mode, e.g. ``GeneratorConfig.realistic()``, are the two first of
them at ``realistic`` and ``tributary``); like the noise factors they make
campaigns of their own.

Designs. ``"one_at_a_time"`` (the default: its size grows with the sum of the
numbers of levels, not their product) runs the base cell and, for every factor
of the grid, one cell per level that differs from the base, all other factors
at the base. ``"product"`` runs the full factorial product of the grid's
levels (factors not in the grid at the base); it is refused beyond
``max_cells`` cells.

Each cell identifies a small synthetic campaign (``n_events`` events, their
duration and seed) with its settings and is scored by
:func:`vivbench.validate.campaign_recovery`: coverage (share of window-
equations flagged identifiable), regime accuracy overall and on identifiable
windows (beside ``truth_majority_share``, the share of the most common true
regime: the accuracy of always answering it), median relative error of the identified dA/dt on active windows
(on the measured and on the true (A, U)) beside the same error on the true (A, U) energy-weighted over the
windows' samples (``rhs_error_true_AU_energy``: the large amplitudes the median hides), and
the wall and CPU time of the identification (reading the events, identifying,
writing the results; not the scoring). Cells that differ only in identification
settings share one campaign: campaigns are generated once per (accel_noise,
anemometer_noise, turbulence_intensity, aero, felt_wind, drift) and the seed, and reused from an
earlier run into the same directory when their configuration matches.
Campaigns, then cells, run through :func:`vivbench.core.parallel.run_tasks`
(local processes or dask); the table does not depend on the worker count or
the completion order (wall times aside).

Outputs in ``OUT``: ``compare.csv`` (one row per cell, by cell id),
``compare_<factor>.png`` (metrics against the levels of each factor of the
grid), ``summary.json``; the campaigns in ``OUT/campaigns/`` and the cells'
result files in ``OUT/cells/<cell_id>/``.
"""

from __future__ import annotations

import csv
import dataclasses
import io as _io
import itertools
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vivbench.preprocess.derivative import DERIVATIVE_METHODS
from vivbench.library.basis import SCALINGS
from vivbench.core.toml import load_toml
from vivbench.regression.optimizers import OPTIMIZERS
from vivbench.synth.config import AERO_MODES, FELT_WIND_MODES
from vivbench.core.errors import InputError, error_line
from vivbench.validate.methods import BUILTIN_METHODS, check_method_spec

__all__ = ["FACTORS", "METHOD_FACTOR", "DESIGNS", "BASE_LEVELS", "CompareConfig", "CompareResult", "compare_config_from_dict",
           "load_compare_config", "compare_cells", "plan", "run_comparison"]

FACTORS = ("derivative", "scaling", "optimizer", "window", "accel_noise", "anemometer_noise", "turbulence_intensity",
           "aero", "felt_wind", "drift")
DESIGNS = ("one_at_a_time", "product")
BASE_LEVELS = {
    "derivative": "tv",
    "scaling": "scaled",
    "optimizer": "stlsq",
    "window": 50.0,
    "accel_noise": 1.0,
    "anemometer_noise": 0.01,
    "turbulence_intensity": 0.08,
    "aero": "in_library",
    "felt_wind": "anemometer",
    "drift": 0.0,
}
_CATEGORICAL = {"derivative": DERIVATIVE_METHODS, "scaling": SCALINGS, "optimizer": OPTIMIZERS,
                "aero": AERO_MODES, "felt_wind": FELT_WIND_MODES}
# Axis labels with units for the plots.
_LABELS = {
    "derivative": "dA/dt method",
    "scaling": "library basis",
    "optimizer": "sparse regression",
    "window": "window length (s)",
    "accel_noise": "accelerometer noise floor (x 30 micro-g/sqrt(Hz))",
    "anemometer_noise": "anemometer error (relative rms, -)",
    "turbulence_intensity": "turbulence intensity sigma_u/U (-)",
    "aero": "aerodynamic functions (generator mode)",
    "felt_wind": "wind felt by the deck",
    "drift": "daily damping drift amplitude (-)",
}
#: The method factor (docs/methods.md): not in FACTORS, so that grids without it keep their table.
METHOD_FACTOR = "method"
_ALL_FACTORS = FACTORS + (METHOD_FACTOR,)
_LABELS[METHOD_FACTOR] = "method"
_CAMPAIGN_FACTORS = ("accel_noise", "anemometer_noise", "turbulence_intensity", "aero", "felt_wind", "drift")
_METRICS = ("n_scored", "truth_majority_share", "coverage", "accuracy_all", "accuracy_identifiable", "accuracy_not_identifiable",
            "rhs_median_rel_error", "rhs_median_rel_error_active", "rhs_error_true_AU_median_active",
            "rhs_error_true_AU_energy", "no_model_share", "wall_time_s",
            "wall_time_per_event_s", "cpu_time_s")
_COLUMNS = ("cell_id", "varied") + FACTORS + ("n_events",) + _METRICS + ("error",)
_METHOD_METRICS = ("curve_error_linear", "curve_error_total", "curve_error_energy", "simulation_nmse",
                   "simulation_covered", "fit_time_s")
_METHOD_COLUMNS = (("cell_id", "varied") + FACTORS + (METHOD_FACTOR, "n_events") + _METRICS + _METHOD_METRICS
                   + ("error",))


def _has_method(config) -> bool:
    return METHOD_FACTOR in config.base


def _columns(config) -> tuple:
    return _METHOD_COLUMNS if _has_method(config) else _COLUMNS


def _categorical(factor: str) -> bool:
    return factor in _CATEGORICAL or factor == METHOD_FACTOR


def _check_level(factor: str, value, where: str):
    """A valid level of ``factor`` (normalised: floats for numeric factors)."""
    if factor == METHOD_FACTOR:
        try:
            return check_method_spec(value)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
    if factor in _CATEGORICAL:
        allowed = _CATEGORICAL[factor]
        if value not in allowed:
            raise InputError(f"{where}: {factor} level {value!r} is not one of {', '.join(allowed)}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}: {factor} levels must be finite numbers; got {value!r}")
    value = float(value)
    if factor == "window" and not value > 0:
        raise InputError(f"{where}: window must be > 0 s; got {value}")
    if factor in ("accel_noise", "anemometer_noise") and value < 0:
        raise InputError(f"{where}: {factor} must be >= 0; got {value}")
    if factor == "turbulence_intensity" and not 0 <= value < 0.5:
        raise InputError(f"{where}: turbulence_intensity must be in [0, 0.5); got {value}")
    if factor == "drift" and not 0 <= value < 1:
        raise InputError(f"{where}: drift must be in [0, 1) (relative damping drift amplitude); got {value}")
    return value


@dataclass(frozen=True, kw_only=True)
class CompareConfig:
    """A method comparison: design, base cell, grid of levels and the campaign of every cell.

    Attributes
    ----------
    design : "one_at_a_time" (default) or "product", see the module docstring
    base : factor -> level of the base cell; missing factors take :data:`BASE_LEVELS`
    grid : factor -> tuple of levels to compare (at least one factor, levels distinct)
    n_events : events per campaign
    duration : (min, max) event duration, s
    seed : campaign seed; also the seed of the ensemble optimiser's bootstrap samples
    step_ratio : window step as a share of the window length (the paper: 0.5)
    active_share : share of an event's RMS true dA/dt above which a window counts as active
    max_cells : largest number of cells accepted
    """

    design: str = "one_at_a_time"
    base: dict = field(default_factory=dict)
    grid: dict = field(default_factory=dict)
    n_events: int = 2
    duration: tuple[float, float] = (1200.0, 1200.0)
    seed: int = 0
    step_ratio: float = 0.5
    active_share: float = 0.1
    max_cells: int = 500

    def __post_init__(self) -> None:
        if self.design not in DESIGNS:
            raise InputError(f"design must be one of {', '.join(DESIGNS)}; got {self.design!r}")
        unknown = sorted(set(self.base) - set(_ALL_FACTORS))
        if unknown:
            raise InputError(f"[base]: unknown factors {unknown}; allowed: {', '.join(_ALL_FACTORS)}")
        unknown = sorted(set(self.grid) - set(_ALL_FACTORS))
        if unknown:
            raise InputError(f"[grid]: unknown factors {unknown}; allowed: {', '.join(_ALL_FACTORS)}")
        if not self.grid:
            raise InputError(f"[grid] must name at least one factor with its levels; factors: {', '.join(_ALL_FACTORS)}")
        base = dict(BASE_LEVELS)
        if METHOD_FACTOR in self.grid or METHOD_FACTOR in self.base:
            base[METHOD_FACTOR] = "windows"
        for k, v in self.base.items():
            base[k] = _check_level(k, v, "[base]")
        grid = {}
        for k in _ALL_FACTORS:  # canonical factor order
            if k not in self.grid:
                continue
            levels = self.grid[k]
            if isinstance(levels, (str, bytes)) or not isinstance(levels, (list, tuple)) or not levels:
                raise InputError(f"[grid]: {k} must be a non-empty list of levels; got {levels!r}")
            levels = tuple(_check_level(k, v, "[grid]") for v in levels)
            if len(set(levels)) != len(levels):
                raise InputError(f"[grid]: {k} has repeated levels {list(levels)}")
            grid[k] = levels
        object.__setattr__(self, "base", base)
        object.__setattr__(self, "grid", grid)
        if METHOD_FACTOR in base:
            from vivbench.validate.methods import resolve_method

            # A plug-in that cannot be imported or built fails here, in one line, before any campaign is made.
            for spec in {base[METHOD_FACTOR], *grid.get(METHOD_FACTOR, ())} - set(BUILTIN_METHODS):
                resolve_method(spec)
        object.__setattr__(self, "duration", tuple(float(x) for x in self.duration))
        if isinstance(self.n_events, bool) or not isinstance(self.n_events, int) or not 1 <= self.n_events <= 1000:
            raise InputError(f"[campaign] events must be an integer in 1..1000; got {self.n_events!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise InputError(f"[campaign] seed must be an integer >= 0; got {self.seed!r}")
        lo, hi = self.duration
        if not 120.0 <= lo <= hi <= 21600.0:
            raise InputError(f"[campaign] duration must be [min, max] seconds with 120 <= min <= max <= 21600; got {list(self.duration)}")
        windows = [base["window"]] + list(grid.get("window", ()))
        if max(windows) > lo / 4:
            raise InputError(f"window levels must be at most a quarter of the shortest event ({lo:g} s); got {max(windows):g} s")
        if not 0 < self.step_ratio <= 1:
            raise InputError(f"step_ratio must be in (0, 1]; got {self.step_ratio}")
        if not 0 <= self.active_share < 1:
            raise InputError(f"active_share must be in [0, 1); got {self.active_share}")
        n = len(compare_cells(self))
        if n > self.max_cells:
            raise InputError(f"the {self.design} design has {n} cells, more than max_cells = {self.max_cells}; "
                             "use design = \"one_at_a_time\", fewer levels, or raise max_cells")

    def to_dict(self) -> dict:
        return {"design": self.design, "base": self.base, "grid": {k: list(v) for k, v in self.grid.items()},
                "campaign": {"events": self.n_events, "duration": list(self.duration), "seed": self.seed},
                "step_ratio": self.step_ratio, "active_share": self.active_share, "max_cells": self.max_cells}


_TOP_KEYS = {"design", "base", "grid", "campaign", "step_ratio", "active_share", "max_cells"}
_CAMPAIGN_KEYS = {"events": "n_events", "duration": "duration", "seed": "seed"}


def compare_config_from_dict(data: dict) -> CompareConfig:
    """The configuration from its TOML layout (see :func:`load_compare_config`)."""
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise InputError(f"unknown keys {unknown}; allowed: {sorted(_TOP_KEYS)}")
    kwargs = {k: data[k] for k in ("design", "base", "grid", "step_ratio", "active_share", "max_cells") if k in data}
    camp = data.get("campaign", {})
    if not isinstance(camp, dict):
        raise InputError("[campaign] must be a table with events, duration, seed")
    unknown = sorted(set(camp) - set(_CAMPAIGN_KEYS))
    if unknown:
        raise InputError(f"[campaign]: unknown keys {unknown}; allowed: {sorted(_CAMPAIGN_KEYS)}")
    for key, name in _CAMPAIGN_KEYS.items():
        if key in camp:
            kwargs[name] = camp[key]
    if "duration" in kwargs:
        d = kwargs["duration"]
        d = [d, d] if isinstance(d, (int, float)) and not isinstance(d, bool) else d
        if not isinstance(d, (list, tuple)) or len(d) != 2:
            raise InputError(f"[campaign] duration must be seconds or [min, max] seconds; got {kwargs['duration']!r}")
        kwargs["duration"] = tuple(d)
    for key in ("base", "grid"):
        if key in kwargs and not isinstance(kwargs[key], dict):
            raise InputError(f"[{key}] must be a table of factors")
    return CompareConfig(**kwargs)


def load_compare_config(path: str | Path) -> CompareConfig:
    """Read a comparison grid from TOML; errors name the file.

    Layout::

        design = "one_at_a_time"        # or "product"
        [campaign]
        events = 2
        duration = [600.0, 600.0]       # s, (min, max)
        seed = 0
        [base]                          # optional; defaults: BASE_LEVELS
        window = 50.0
        [grid]
        optimizer = ["stlsq", "sr3", "ensemble"]
        window = [30.0, 50.0, 100.0]
        aero = ["in_library", "realistic"]        # realism factors: aero, felt_wind, drift
        felt_wind = ["anemometer", "tributary"]
        drift = [0.0, 0.3]
    """
    return load_toml(path, compare_config_from_dict, "grid file")


def compare_cells(config: CompareConfig) -> list[dict]:
    """The cells of the design, in cell-id order: dicts with ``cell_id``, ``varied`` and every factor."""
    base = dict(config.base)
    cells = []
    if config.design == "one_at_a_time":
        cells.append(dict(base, varied="base"))
        for factor, levels in config.grid.items():
            for level in levels:
                if level != base[factor]:
                    cells.append(dict(base, **{factor: level}, varied=factor))
    else:
        names = list(config.grid)
        for combo in itertools.product(*(config.grid[k] for k in names)):
            cells.append(dict(base, **dict(zip(names, combo)), varied="product"))
    width = max(3, len(str(len(cells) - 1)))
    return [dict(c, cell_id=f"c{i:0{width}d}") for i, c in enumerate(cells)]


def _campaign_key(cell: dict) -> tuple:
    return tuple(cell[k] for k in _CAMPAIGN_FACTORS)


def _campaign_config(config: CompareConfig, key: tuple):
    from vivbench.synth import AeroConfig, CampaignConfig, ChangesConfig, GeneratorConfig, SensorConfig, WindConfig

    accel, anem, ti, aero, felt, drift = key
    default = GeneratorConfig.in_library()
    generator = dataclasses.replace(
        default,
        sensors=dataclasses.replace(default.sensors, noise_density=SensorConfig().noise_density * accel),
        wind=dataclasses.replace(default.wind, noise=anem, felt_wind=felt,
                                 turbulence=dataclasses.replace(WindConfig().turbulence, intensity=ti)),
        aero=AeroConfig.from_mode(aero),
        changes=ChangesConfig(drift_amplitude=drift),
    )
    return CampaignConfig(n_events=config.n_events, seed=config.seed, duration=config.duration, generator=generator)


def _make_campaign(task: dict) -> list[str]:
    """Generate one campaign (or reuse it when its recorded configuration matches)."""
    from vivbench.io.netcdf import atomic_path
    from vivbench.io.event import list_events
    from vivbench.synth import config_to_dict, generate_campaign

    out = Path(task["dir"])
    campaign = task["campaign"]
    record = json.dumps({"n_events": campaign.n_events, "seed": campaign.seed, "duration": list(campaign.duration),
                         "generator": config_to_dict(campaign.generator)}, sort_keys=True)
    marker = out / "campaign.json"
    if marker.is_file() and marker.read_text() == record:
        files = list_events(out)
        if len(files) == campaign.n_events:
            return [str(f) for f in files]
    result = generate_campaign(campaign, out, workers=1)
    if result.failures:
        first = sorted(result.failures.items())[0]
        raise RuntimeError(f"campaign {out.name}: event {first[0]} failed: {first[1]}")
    with atomic_path(marker) as tmp:
        tmp.write_text(record)
    return [str(f) for f in result.files]


def _identify_config(cell: dict, config: CompareConfig):
    from vivbench.preprocess.derivative import Derivative
    from vivbench.analysis.identify import IdentifyConfig

    return IdentifyConfig(derivative=Derivative.for_envelope(cell["derivative"]), window=cell["window"],
                          step=cell["window"] * config.step_ratio, scaling=cell["scaling"],
                          optimizer=cell["optimizer"], seed=config.seed)


def _run_cell_reported(task: dict) -> dict:
    """:func:`_run_cell`; a failure that is not bad input (or an OSError) is reported as an internal error."""
    try:
        return _run_cell(task)
    except (InputError, OSError):
        raise
    except Exception as exc:
        raise RuntimeError(error_line(exc)) from exc


def _run_cell(task: dict) -> dict:
    """Identify one cell's campaign with its settings and score it; returns the metrics."""
    from vivbench.analysis.identify import identify_event
    from vivbench.io.result import write_result
    from vivbench.io.event import read_event
    from vivbench.validate.recovery import campaign_recovery

    cell, config = task["cell"], task["config"]
    ident = _identify_config(cell, config)
    out = Path(task["dir"])
    results, no_model, total = [], 0, 0
    t0, c0 = time.perf_counter(), time.process_time()
    for path in task["files"]:
        ds = identify_event(read_event(path), ident, source=Path(path).name)
        reg = ds["regime"].values
        no_model += int(np.sum(reg == 0))
        total += reg.size
        results.append(write_result(ds, out))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if METHOD_FACTOR in cell:
        return _score_method_cell(cell, config, task["files"], results, wall, cpu)
    scores = campaign_recovery(task["files"], results, active_share=config.active_share)
    return {
        "n_scored": scores["n"],
        # Accuracy of always answering the most common true regime: the chance level of accuracy_all.
        "truth_majority_share": max(scores["truth_regime_shares"].values()),
        "coverage": scores["coverage"],
        "accuracy_all": scores["accuracy_all"],
        "accuracy_identifiable": scores["accuracy_identifiable"],
        "accuracy_not_identifiable": scores["accuracy_not_identifiable"],
        "rhs_median_rel_error": scores["rhs_median_rel_error"],
        "rhs_median_rel_error_active": scores["rhs_median_rel_error_active"],
        # on the truth's own (A, U): scored for truths outside the library too
        "rhs_error_true_AU_median_active": scores["rhs_error_true_AU_median_active"],
        "rhs_error_true_AU_energy": scores["rhs_error_true_AU_energy"],
        "no_model_share": no_model / total if total else float("nan"),
        "wall_time_s": wall,
        "wall_time_per_event_s": wall / len(task["files"]),
        # CPU time of the worker: less sensitive than wall time to other load on the machine.
        "cpu_time_s": cpu,
    }


def _score_method_cell(cell: dict, config: CompareConfig, event_files, results, wall: float, cpu: float) -> dict:
    """Fit the cell's method on the identification's records and score it (:func:`score_fitted`)."""
    from vivbench.io.result import read_result
    from vivbench.validate.methods import FittedWindows, fit_method, resolve_method, score_fitted, scoring_inputs

    spec = cell[METHOD_FACTOR]
    records, truths, windows = scoring_inputs(event_files, results)
    w0, c0 = time.perf_counter(), time.process_time()
    if spec == "windows":
        # The identification's own window models, regimes and verdicts: its wall time is the fit.
        fitted, fit_time = FittedWindows.from_results([read_result(r) for r in results]), wall
    else:
        fitted, fit_time = fit_method(resolve_method(spec), records)
    wall += time.perf_counter() - w0
    cpu += time.process_time() - c0
    scores = score_fitted(fitted, records, truths, windows=windows, active_share=config.active_share,
                          fit_time_s=fit_time)
    out = {k: scores[k] for k in ("n_scored", "truth_majority_share", "coverage", "accuracy_all",
                                  "accuracy_identifiable", "accuracy_not_identifiable", "rhs_median_rel_error",
                                  "rhs_median_rel_error_active", "rhs_error_true_AU_median_active",
                                  "rhs_error_true_AU_energy", "no_model_share") + _METHOD_METRICS}
    out.update(wall_time_s=wall, wall_time_per_event_s=wall / len(event_files), cpu_time_s=cpu)
    return out


@dataclass(frozen=True)
class CompareResult:
    """Rows of ``compare.csv`` (by cell id), the files written and the failures (cell or campaign -> message)."""

    rows: list[dict]
    table: Path
    figures: list[Path]
    summary: Path
    failures: dict[str, str]


def run_comparison(config: CompareConfig, out_dir: str | Path, *, workers: int = 1, scheduler: str | None = None,
                   progress: Callable[[str], None] | None = None) -> CompareResult:
    """Run every cell of the comparison and write the table, the plots and the summary.

    Parameters
    ----------
    config : CompareConfig
    out_dir : output directory (created)
    workers, scheduler : see :func:`vivbench.core.parallel.run_tasks` (with a scheduler address,
        ``out_dir`` must be on a file system the workers share)
    progress : optional callback, called with ``"campaign"`` or ``"cell"`` as each task finishes
        (``n_campaigns + n_cells`` calls; see :func:`plan`)

    Returns
    -------
    CompareResult
        A cell that fails (or whose campaign failed) has its metrics NaN and
        its message in ``error``; the others finish.
    """
    from vivbench.core.parallel import run_tasks

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cells = compare_cells(config)
    keys = sorted({_campaign_key(c) for c in cells})
    camp_tasks = [{"dir": str(out / "campaigns" / f"k{i:02d}"), "campaign": _campaign_config(config, k)}
                  for i, k in enumerate(keys)]
    files: dict[tuple, list[str]] = {}
    failures: dict[str, str] = {}
    for o in run_tasks(_make_campaign, camp_tasks, workers=workers, scheduler=scheduler):
        if o.ok:
            files[keys[o.index]] = o.value
        else:
            failures[f"campaign {Path(camp_tasks[o.index]['dir']).name}"] = o.error
        if progress is not None:
            progress("campaign")

    runnable = [c for c in cells if _campaign_key(c) in files]
    tasks = [{"cell": c, "config": config, "files": files[_campaign_key(c)], "dir": str(out / "cells" / c["cell_id"])}
             for c in runnable]
    metrics: dict[str, dict] = {}
    errors: dict[str, str] = {}
    for c in cells:
        if _campaign_key(c) not in files:
            errors[c["cell_id"]] = "campaign failed"
            if progress is not None:
                progress("cell")
    for o in run_tasks(_run_cell_reported, tasks, workers=workers, scheduler=scheduler):
        cid = runnable[o.index]["cell_id"]
        if o.ok:
            metrics[cid] = o.value
        else:
            errors[cid] = o.error
        if progress is not None:
            progress("cell")
    failures.update({f"cell {k}": v for k, v in sorted(errors.items())})

    rows = []
    for c in cells:  # cell-id order, whatever the completion order
        row = {k: c[k] for k in ("cell_id", "varied") + FACTORS}
        if _has_method(config):
            row[METHOD_FACTOR] = c[METHOD_FACTOR]
        row["n_events"] = config.n_events
        m = metrics.get(c["cell_id"], {})
        row.update({k: m.get(k, float("nan")) for k in _METRICS + (_METHOD_METRICS if _has_method(config) else ())})
        row["error"] = errors.get(c["cell_id"], "")
        rows.append(row)
    table = _write_table(rows, out / "compare.csv", _columns(config))
    figures = [_plot_factor(rows, config, f, out / f"compare_{f}.png") for f in config.grid]
    summary = _write_summary(rows, config, out / "summary.json")
    return CompareResult(rows=rows, table=table, figures=figures, summary=summary, failures=failures)


def plan(config: CompareConfig) -> tuple[int, int]:
    """(campaigns, cells) the comparison runs: the number of progress calls is their sum."""
    cells = compare_cells(config)
    return len({_campaign_key(c) for c in cells}), len(cells)


def _fmt(value) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return f"{value:.6g}"
    return str(value)


def _write_table(rows: list[dict], path: Path, columns: tuple = _COLUMNS) -> Path:
    from vivbench.io.netcdf import atomic_path

    buf = _io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: _fmt(r[k]) for k in columns})
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue())
    return path


def _levels(config: CompareConfig, factor: str) -> list:
    levels = list(config.grid[factor])
    if config.design == "one_at_a_time" and config.base[factor] not in levels:
        levels.append(config.base[factor])
    if not _categorical(factor):
        levels.sort()
    return levels


def _plot_factor(rows: list[dict], config: CompareConfig, factor: str, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vivbench.io.netcdf import atomic_path

    levels = _levels(config, factor)
    if config.design == "one_at_a_time":
        sel = [r for r in rows if r["varied"] in ("base", factor)]
    else:
        sel = rows
    sel = [dict(r, cpu_time_per_event_s=r["cpu_time_s"] / r["n_events"]) for r in sel]
    if _has_method(config):
        sel = [dict(r, fit_time_per_event_s=r["fit_time_s"] / r["n_events"]) for r in sel]
    pos = {lv: i for i, lv in enumerate(levels)}
    x = np.array([pos[r[factor]] for r in sel], dtype=float)
    panels = [
        ("regime recovery (-)", [("coverage", "coverage (identifiable share)"), ("accuracy_all", "accuracy, all windows"),
                                 ("accuracy_identifiable", "accuracy, identifiable windows"),
                                 ("truth_majority_share", "most common true regime (chance level)")], False),
        ("rel. error of dA/dt (-)", [("rhs_median_rel_error_active", "median, active windows, exact matrix"),
                                     ("rhs_error_true_AU_energy", "energy-weighted, true (A, U)")], True),
        ("identification time\nper event (s)", [("wall_time_per_event_s", "wall time"),
                                                ("cpu_time_per_event_s", "CPU time")], False),
    ]
    if _has_method(config):
        # Realistic truths have no exact matrix: the dA/dt error on the true (A, U) is the one always scored.
        panels[1] = ("rel. error of dA/dt (-)",
                     [("rhs_error_true_AU_median_active", "median, active windows, true (A, U)"),
                      ("rhs_error_true_AU_energy", "energy-weighted, true (A, U)"),
                      ("rhs_median_rel_error_active", "median, measured (A, U), exact matrix")], True)
        panels[2] = ("time per event (s)", [("wall_time_per_event_s", "wall time (identification + fit)"),
                                            ("cpu_time_per_event_s", "CPU time"),
                                            ("fit_time_per_event_s", "method fit (windows: identification)")], False)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), constrained_layout=True)
    for ax, (ylabel, metrics, logy) in zip(axes, panels):
        for k, (metric, label) in enumerate(metrics):
            y = np.array([r.get(metric, math.nan) for r in sel], dtype=float)
            colour = f"C{k}"
            ax.plot(x, y, "o", color=colour, alpha=0.5, label=label)
            mean = [np.nanmean(y[x == i]) if np.isfinite(y[x == i]).any() else np.nan for i in range(len(levels))]
            ax.plot(range(len(levels)), mean, "-", color=colour)
        ax.set_xticks(range(len(levels)))
        ax.set_xticklabels([_fmt(lv) for lv in levels], rotation=20 if _categorical(factor) else 0)
        ax.set_xlabel(_LABELS[factor])
        ax.set_ylabel(ylabel)
        vals = np.array([r[metrics[0][0]] for r in sel], dtype=float)
        vals = vals[np.isfinite(vals) & (vals > 0)]
        if logy and vals.size and vals.max() > 10 * vals.min():  # log only when the spread needs it
            ax.set_yscale("log")
        if metrics[0][1]:
            ax.legend(fontsize=7, loc="best")
        if metrics[0][0] == "coverage":
            ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
    design = "one at a time around the base cell" if config.design == "one_at_a_time" else "full product (line: mean per level)"
    fig.suptitle(f"Method comparison: {factor} ({design}; {config.n_events} events, seed {config.seed})", fontsize=10)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    return path


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, (np.floating, np.integer)):
        return _clean(v.item())
    return v


def _write_summary(rows: list[dict], config: CompareConfig, path: Path) -> Path:
    from vivbench.io.netcdf import atomic_path

    ok = [r for r in rows if not r["error"]]
    summary = {"design": config.design, "n_cells": len(rows), "n_failed": len(rows) - len(ok),
               "n_events_per_cell": config.n_events}
    base = next((r for r in rows if r["varied"] == "base"), None)
    if base is not None:
        for k in ("coverage", "accuracy_all", "accuracy_identifiable", "rhs_median_rel_error_active",
                  "rhs_error_true_AU_median_active", "rhs_error_true_AU_energy"):
            summary[f"base_{k}"] = base.get(k, math.nan)
    for metric, better in (("rhs_median_rel_error_active", min), ("accuracy_all", max), ("coverage", max)):
        scored = [r for r in ok if math.isfinite(r[metric])]
        if scored:
            best = better(scored, key=lambda r: r[metric])
            summary[f"best_{metric}"] = best[metric]
            summary[f"best_{metric}_cell"] = best["cell_id"]
    times = [r["wall_time_s"] for r in ok]
    if times:
        summary["median_wall_time_per_cell_s"] = float(np.median(times))
        summary["total_wall_time_cells_s"] = float(np.sum(times))
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps({k: _clean(v) for k, v in summary.items()}, indent=2, sort_keys=True) + "\n")
    return path
