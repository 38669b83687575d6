"""Monte-Carlo recovery sweeps: many synthetic campaigns, each generated, identified and scored.

A sweep varies the measurement noise, the turbulence, structural or
aerodynamic parameters and the realism switches of docs/concepts.md (no inverse crime) (aerodynamic
functions, felt wind, damping drift) of the synthetic bridge over a grid (every combination)
and/or ranges (drawn per campaign), and records for every campaign how well
the identification chain recovers the truth (:func:`campaign_recovery`).

One task is one campaign. Its seeds are fixed by the sweep configuration
alone (``numpy.random.SeedSequence``), so a task gives the same numbers
wherever and in whatever order it runs: in this process, in local worker
processes or on a dask cluster (:func:`vivbench.core.parallel.run_tasks`).
Replicate ``r`` uses the same campaign seed at every grid point (common random
numbers): the wind scripts and noise draws are paired across grid points, so
differences between points come from the parameters, not from the draws.

Results are journalled (``OUT/sweep.jsonl``, one line per finished task,
flushed to disk) and ``OUT/sweep.csv`` is rebuilt from the journal, sorted by
task id, after each task: a sweep stopped part-way (Ctrl-C, a kill, a crash)
resumes where it stopped, and a half-written last line is dropped.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import shutil
import tempfile
from collections.abc import Callable
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vivbench.core.toml import load_toml
from vivbench.preprocess.derivative import Derivative
from vivbench.analysis.identify import IdentifyConfig, identify_files
from vivbench.preprocess.config import PreprocessConfig
from vivbench.io.netcdf import atomic_path
from vivbench.core.parallel import parse_scheduler, run_tasks
from vivbench.synth.campaign import CampaignConfig, generate_campaign
from vivbench.synth.config import GeneratorConfig, config_from_dict, config_to_dict
from vivbench.validate.journal import append as journal_append
from vivbench.validate.journal import check_record
from vivbench.validate.journal import load as journal_load
from vivbench.validate.journal import write_table
from vivbench.validate.recovery import campaign_recovery
from vivbench.validate.sweep_figures import plot_recovery, sweep_summary
from vivbench.validate.sweep_parameters import PARAMETERS, SWEEP_PARAMETERS
from vivbench.core.errors import InputError, error_line
from vivbench.core.lock import exclusive_directory

__all__ = [
    "SWEEP_PARAMETERS",
    "METRIC_COLUMNS",
    "SweepConfig",
    "SweepTask",
    "SweepResult",
    "load_sweep_config",
    "sweep_config_from_dict",
    "sweep_tasks",
    "run_sweep_task",
    "run_sweep",
]


#: Per-campaign metrics of the sweep table (see :func:`campaign_recovery`).
METRIC_COLUMNS = (
    "events_failed",
    "n_window_equations",
    "coverage",
    "accuracy_all",
    "accuracy_identifiable",
    "accuracy_not_identifiable",
    "truth_majority_share",
    "rhs_median_rel_error",
    "rhs_median_rel_error_active",
    "active_share",
    "rhs_error_true_AU_median_active",
    "rhs_error_true_AU_energy",
    "campaign_model_coverage",
    "campaign_model_accuracy_all",
    "campaign_model_accuracy_identifiable",
    "campaign_model_rhs_median_rel_error_active",
    "campaign_model_rhs_error_true_AU_median_active",
    "campaign_model_rhs_error_true_AU_energy",
    "truth_share_regime1",
    "truth_share_regime2",
    "truth_share_regime3",
    "truth_share_regime4",
)
#: Campaign models a sweep can score (``SweepConfig.campaign_model``).
CAMPAIGN_MODELS = ("varying", "pooled")

_ID_COLUMNS = ("task_id", "point", "replicate", "campaign_seed", "n_events")
COLUMNS = (*_ID_COLUMNS, *PARAMETERS, *METRIC_COLUMNS, "error")


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{what} must be a number; got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise InputError(f"{what} must be finite; got {value!r}")
    return out


def _apply(gen: GeneratorConfig, values: dict[str, float], where: str) -> GeneratorConfig:
    for name, value in values.items():
        try:
            gen = PARAMETERS[name].apply(gen, value)
        except (ValueError, TypeError) as exc:
            raise InputError(f"{where} {name} = {value!r}: {exc}") from None
    return gen


# --------------------------------------------------------------------- config


@dataclass(frozen=True, kw_only=True)
class SweepConfig:
    """A Monte-Carlo recovery sweep.

    Attributes
    ----------
    seed : base seed of the sweep (campaign seeds and range draws derive from it)
    n_campaigns : campaigns (replicates) per grid point; default 1, or ``len(seeds)``
    seeds : explicit campaign seeds, one per replicate (instead of deriving them from ``seed``)
    n_events : events per campaign
    duration : (min, max) event duration, s
    grid : parameter -> values; every combination is a grid point (``SWEEP_PARAMETERS``)
    ranges : parameter -> (low, high); each campaign draws a value uniformly from its own stream
    generator : base generator configuration that the grid and ranges modify
    identify : identification settings
    campaign_model : "varying" (default, :class:`~vivbench.models.VaryingCoefficientSINDy`, the default of
        ``vivbench pool``) or "pooled" (:class:`~vivbench.models.PooledSINDy`, the paper's class): the campaign
        model behind the ``pooled_*`` columns, fitted with the campaign's seed
    """

    seed: int = 0
    n_campaigns: int | None = None
    seeds: tuple[int, ...] | None = None
    n_events: int = 2
    duration: tuple[float, float] = (1200.0, 1200.0)
    grid: tuple[tuple[str, tuple[float, ...]], ...] = ()
    ranges: tuple[tuple[str, tuple[float, float]], ...] = ()
    generator: GeneratorConfig = field(default_factory=GeneratorConfig)
    identify: IdentifyConfig = field(default_factory=IdentifyConfig)
    campaign_model: str = "varying"

    def __post_init__(self) -> None:
        if self.campaign_model not in CAMPAIGN_MODELS:
            raise InputError(f"campaign_model must be one of {', '.join(CAMPAIGN_MODELS)}; got {self.campaign_model!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise InputError(f"seed must be a non-negative integer; got {self.seed!r}")
        if self.seeds is not None:
            seeds = tuple(self.seeds)
            if not seeds or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds):
                raise InputError(f"seeds must be a non-empty list of non-negative integers; got {self.seeds!r}")
            if len(set(seeds)) != len(seeds):
                raise InputError(f"seeds must be distinct (a repeated seed repeats a campaign); got {list(seeds)}")
            if self.n_campaigns is not None and self.n_campaigns != len(seeds):
                raise InputError(f"n_campaigns ({self.n_campaigns}) disagrees with the {len(seeds)} seeds given; "
                                 "give one of them")
            object.__setattr__(self, "seeds", tuple(int(s) for s in seeds))
            object.__setattr__(self, "n_campaigns", len(seeds))
        elif self.n_campaigns is None:
            object.__setattr__(self, "n_campaigns", 1)
        n = self.n_campaigns
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= 100000:
            raise InputError(f"n_campaigns (campaigns per grid point) must be an integer in 1..100000; got {n!r}")
        if isinstance(self.n_events, bool) or not isinstance(self.n_events, (int, np.integer)):
            raise InputError(f"n_events (events per campaign) must be an integer; got {self.n_events!r}")
        # The campaign's own checks give the messages for the ranges of n_events and duration.
        CampaignConfig(n_events=self.n_events, seed=0, duration=self.duration)
        if self.campaign_model == "varying" and self.n_events < 2:
            raise InputError(f'campaign_model "varying" needs n_events >= 2 (it cross-validates over events); got '
                             f'{self.n_events}: give more events or campaign_model = "pooled"')
        object.__setattr__(self, "duration", tuple(float(x) for x in self.duration))
        for name in ("generator", "identify"):
            expected = GeneratorConfig if name == "generator" else IdentifyConfig
            if not isinstance(getattr(self, name), expected):
                raise InputError(f"{name} must be a {expected.__name__}; got {type(getattr(self, name)).__name__}")
        object.__setattr__(self, "grid", self._axes(self.grid, "grid"))
        object.__setattr__(self, "ranges", self._axes(self.ranges, "ranges"))
        both = set(dict(self.grid)) & set(dict(self.ranges))
        if both:
            raise InputError(f"{sorted(both)} in both [grid] and [ranges]; a parameter is either a grid axis or a range")
        if self.n_tasks > 100000:
            raise InputError(f"the sweep has {self.n_tasks} campaigns (grid points x n_campaigns); at most 100000")
        self._check_values()
        self._check_duration()

    @staticmethod
    def _axes(axes, kind: str) -> tuple:
        items = axes.items() if isinstance(axes, dict) else axes
        out = []
        for item in items:
            try:
                name, values = item
            except (TypeError, ValueError):
                raise InputError(f"[{kind}] must map parameter names to values; got {item!r}") from None
            if name not in PARAMETERS:
                raise InputError(f"[{kind}] unknown parameter {name!r}; allowed: {', '.join(PARAMETERS)}")
            if isinstance(values, (str, bytes)) or not hasattr(values, "__len__"):
                raise InputError(f"[{kind}] {name} must be a list of numbers; got {values!r}")
            vals = tuple(_number(v, f"[{kind}] {name} value") for v in values)
            if kind == "grid":
                if not vals:
                    raise InputError(f"[grid] {name} needs at least one value")
                if len(set(vals)) != len(vals):
                    raise InputError(f"[grid] {name} values must be distinct; got {list(vals)}")
            elif PARAMETERS[name].switch:
                raise InputError(f"[ranges] {name} is a 0/1 switch: give it under [grid], e.g. {name} = [0, 1]")
            elif len(vals) != 2 or not vals[0] <= vals[1]:
                raise InputError(f"[ranges] {name} must be [low, high] with low <= high; got {list(vals)}")
            out.append((name, vals))
        return tuple(out)

    def _check_values(self) -> None:
        for name, values in self.grid:
            for v in values:
                _apply(self.generator, {name: v}, "[grid]")
        for name, (lo, hi) in self.ranges:
            for v in (lo, hi):
                _apply(self.generator, {name: v}, "[ranges]")

    def _check_duration(self) -> None:
        pre = self.identify.preprocess
        f_mode = pre.modal_frequency_hz or self.generator.structure.frequency
        edge = pre.settling_s(f_mode)
        need = 2.0 * edge + max(self.identify.window, pre.min_segment_s)
        if not self.duration[0] > need:
            raise InputError(f"duration: events of {self.duration[0]:g} s hold no identification window once "
                             f"{edge:g} s are dropped at each end; the shortest event must be longer than {need:g} s")

    @property
    def n_points(self) -> int:
        """Number of grid points (1 without a grid)."""
        return math.prod(len(v) for _, v in self.grid)

    @property
    def n_tasks(self) -> int:
        """Number of campaigns in the sweep."""
        return self.n_points * int(self.n_campaigns)

    @property
    def varied(self) -> tuple[str, ...]:
        """Parameters that take more than one value, in registry order."""
        names = {n for n, v in self.grid if len(v) > 1} | {n for n, (lo, hi) in self.ranges if hi > lo}
        return tuple(n for n in PARAMETERS if n in names)

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form (JSON-ready); its hash identifies the sweep in its output directory."""
        return {
            "seed": int(self.seed),
            "n_campaigns": int(self.n_campaigns),
            "seeds": list(self.seeds) if self.seeds is not None else None,
            "n_events": int(self.n_events),
            "duration": list(self.duration),
            "grid": [[name, list(values)] for name, values in self.grid],
            "ranges": [[name, list(values)] for name, values in self.ranges],
            "generator": config_to_dict(self.generator),
            "identify": json.loads(self.identify.to_json()),
            "campaign_model": self.campaign_model,
        }

    def fingerprint(self) -> str:
        """SHA-256 of :meth:`to_dict` (canonical JSON)."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()


_TOP_KEYS = ("seed", "n_campaigns", "seeds", "n_events", "duration", "grid", "ranges", "generator", "identify",
             "campaign_model")
_IDENTIFY_KEYS = ("window", "step", "alpha", "scaling", "tau", "aicc_margin", "fit_tolerance", "thresholds",
                  "derivative", "preprocess", "spike_mad", "min_snr", "optimizer", "seed")


def _identify_from_dict(data: dict) -> IdentifyConfig:
    if not isinstance(data, dict):
        raise InputError(f"[identify] must be a table; got {data!r}")
    unknown = set(data) - set(_IDENTIFY_KEYS)
    if unknown:
        raise InputError(f"unknown keys {sorted(unknown)} in [identify]; allowed: {', '.join(_IDENTIFY_KEYS)}")
    kwargs = dict(data)
    if kwargs.get("spike_mad") is False:  # TOML has no None: false switches despiking off
        kwargs["spike_mad"] = None
    if "derivative" in kwargs:
        d = kwargs["derivative"]
        kwargs["derivative"] = Derivative.for_envelope(d) if isinstance(d, str) else Derivative.for_envelope(**d)
    if "preprocess" in kwargs:
        p = {k: tuple(v) if isinstance(v, list) else v for k, v in kwargs["preprocess"].items()}
        kwargs["preprocess"] = PreprocessConfig(**p)
    return IdentifyConfig(**kwargs)


def sweep_config_from_dict(data: dict[str, Any]) -> SweepConfig:
    """A :class:`SweepConfig` from plain data (the TOML layout of :func:`load_sweep_config`)."""
    if not isinstance(data, dict):
        raise InputError(f"a sweep configuration is a table; got {type(data).__name__}")
    unknown = set(data) - set(_TOP_KEYS)
    if unknown:
        raise InputError(f"unknown keys {sorted(unknown)}; allowed: {', '.join(_TOP_KEYS)}")
    kwargs = {k: v for k, v in data.items() if k not in ("generator", "identify", "grid", "ranges")}
    for key in ("grid", "ranges"):
        if key in data:
            if not isinstance(data[key], dict):
                raise InputError(f"[{key}] must be a table of parameter = [values]; got {data[key]!r}")
            kwargs[key] = tuple(data[key].items())
    if "duration" in kwargs:
        d = kwargs["duration"]
        if isinstance(d, (int, float)) and not isinstance(d, bool):
            d = (d, d)
        if not isinstance(d, (list, tuple)) or len(d) != 2:
            raise InputError(f"duration must be [min, max] seconds (or one number); got {kwargs['duration']!r}")
        kwargs["duration"] = tuple(_number(x, "duration") for x in d)
    if "seeds" in kwargs and not isinstance(kwargs["seeds"], (list, tuple)):
        raise InputError(f"seeds must be a list of non-negative integers; got {kwargs['seeds']!r}")
    try:
        if "generator" in data:
            if not isinstance(data["generator"], dict):
                raise InputError("[generator] must be a table")
            kwargs["generator"] = config_from_dict(data["generator"])
    except (ValueError, TypeError) as exc:
        raise InputError(f"[generator]: {exc}") from None
    try:
        if "identify" in data:
            kwargs["identify"] = _identify_from_dict(data["identify"])
    except (ValueError, TypeError) as exc:
        raise InputError(f"[identify]: {exc}") from None
    return SweepConfig(**kwargs)


def load_sweep_config(path: str | Path) -> SweepConfig:
    """Read a sweep from TOML; errors name the file.

    Layout (every key optional)::

        seed = 0                      # base seed
        n_campaigns = 2               # campaigns per grid point (or seeds = [3, 7])
        n_events = 2                  # events per campaign
        duration = [240.0, 240.0]     # event duration (min, max), s
        campaign_model = "varying"    # the pooled_* columns' model: varying (default) or pooled
        [grid]                        # every combination is a grid point
        noise_density = [30.0, 300.0]
        aero_realistic = [0, 1]       # realism switches (0/1, grid only): aero_realistic, felt_wind_tributary
        drift_amplitude = [0.0, 0.3]
        [ranges]                      # drawn per campaign, uniformly
        turbulence_intensity = [0.04, 0.12]
        [identify]                    # IdentifyConfig: window, step, alpha, optimizer, derivative = "tv",
                                      # spike_mad (false: off), [identify.preprocess] ...
        window = 50.0
        [generator]                   # base generator configuration, as `vivbench synth --config`
        integration_step = 0.02

    Parameters of ``[grid]`` and ``[ranges]``: see ``SWEEP_PARAMETERS``.
    """
    return load_toml(path, sweep_config_from_dict, "sweep file")


# ---------------------------------------------------------------------- tasks


@dataclass(frozen=True, kw_only=True)
class SweepTask:
    """One campaign of a sweep: everything a worker needs, seeds included.

    Attributes
    ----------
    task_id, point, replicate : position in the sweep (task_id = point * n_campaigns + replicate)
    campaign_seed : the campaign's seed (its events' seeds are spawned from it)
    params : value of every sweep parameter in this campaign (name, value), registry order
    campaign : CampaignConfig (its generator has the parameters applied)
    identify : IdentifyConfig
    campaign_model : "varying" or "pooled" (:class:`SweepConfig`)
    work_root : directory for the temporary campaign (None: the system's temporary directory)
    keep_dir : when set, the campaign and its results are written here and kept
    """

    task_id: int
    point: int
    replicate: int
    campaign_seed: int
    params: tuple[tuple[str, float], ...]
    campaign: CampaignConfig
    identify: IdentifyConfig
    campaign_model: str = "varying"
    work_root: str | None = None
    keep_dir: str | None = None

    def describe(self) -> dict[str, Any]:
        """The task's columns of the sweep table."""
        return {"task_id": self.task_id, "point": self.point, "replicate": self.replicate,
                "campaign_seed": self.campaign_seed, "n_events": self.campaign.n_events, **dict(self.params)}


def _campaign_seed(config: SweepConfig, replicate: int) -> int:
    if config.seeds is not None:
        return config.seeds[replicate]
    ss = np.random.SeedSequence(config.seed, spawn_key=(0, replicate))
    return int(ss.generate_state(1, dtype=np.uint32)[0])


def sweep_tasks(config: SweepConfig) -> list[SweepTask]:
    """Every task of a sweep, in task-id order (grid points outer, replicates inner). Cheap: nothing runs."""
    names = [n for n, _ in config.grid]
    points = list(itertools.product(*(v for _, v in config.grid))) if config.grid else [()]
    tasks = []
    for p, values in enumerate(points):
        for r in range(config.n_campaigns):
            chosen = dict(zip(names, values))
            if config.ranges:
                # Each campaign draws its ranges from its own stream, keyed by its position.
                rng = np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(1, p, r)))
                for name, (lo, hi) in config.ranges:
                    u = float(rng.random())
                    chosen[name] = lo + u * (hi - lo)
            gen = _apply(config.generator, chosen, "sweep parameter")
            # Chosen values as given (reading Y1's peak back would add rounding); the others as in effect.
            params = tuple((name, float(chosen[name]) if name in chosen else float(p_.read(gen)))
                           for name, p_ in PARAMETERS.items())
            seed = _campaign_seed(config, r)
            campaign = CampaignConfig(n_events=config.n_events, seed=seed, duration=config.duration, generator=gen)
            tasks.append(SweepTask(task_id=p * config.n_campaigns + r, point=p, replicate=r, campaign_seed=seed,
                                   params=params, campaign=campaign, identify=config.identify,
                                   campaign_model=config.campaign_model))
    return tasks


def _flatten_scores(scores: dict) -> dict[str, float]:
    shares = scores.get("truth_regime_shares", {})
    out = {
        "n_window_equations": int(scores["n"]),
        "coverage": scores["coverage"],
        "accuracy_all": scores["accuracy_all"],
        "accuracy_identifiable": scores["accuracy_identifiable"],
        "accuracy_not_identifiable": scores["accuracy_not_identifiable"],
        "truth_majority_share": max(shares.values()) if shares else float("nan"),
        "rhs_median_rel_error": scores["rhs_median_rel_error"],
        "rhs_median_rel_error_active": scores["rhs_median_rel_error_active"],
        "active_share": scores["active_share"],
        # on the truth's own (A, U) through the models' predict: scored for truths outside the library too
        "rhs_error_true_AU_median_active": scores["rhs_error_true_AU_median_active"],
        # the same energy-weighted over every window sample: the large amplitudes the median hides
        "rhs_error_true_AU_energy": scores["rhs_error_true_AU_energy"],
    }
    for k in (1, 2, 3, 4):
        out[f"truth_share_regime{k}"] = shares.get(k, float("nan"))
    return {k: (int(v) if k == "n_window_equations" else float(v)) for k, v in out.items()}


class CampaignFailed(Exception):
    """A sweep task's campaign could not be generated, identified or scored (message: the cause)."""


def run_sweep_task(task: SweepTask) -> dict[str, Any]:
    """Generate, identify and score one campaign; return its metrics (``METRIC_COLUMNS``).

    Runs in a worker. The campaign lives in a temporary directory that is
    removed afterwards, unless ``task.keep_dir`` is set. Events that fail to
    generate or identify are counted in ``events_failed`` and the others are
    scored; a campaign with no identified event raises ValueError.
    """
    if task.keep_dir is not None:
        root = Path(task.keep_dir)
        root.mkdir(parents=True, exist_ok=True)
    else:
        if task.work_root is not None:
            Path(task.work_root).mkdir(parents=True, exist_ok=True)
        root = Path(tempfile.mkdtemp(prefix=f"t{task.task_id:05d}-", dir=task.work_root))
    try:
        made = generate_campaign(task.campaign, root / "campaign", workers=1)
        written, failures = identify_files(made.files, root / "identify", task.identify, workers=1)
        n_failed = len(made.failures) + len(failures)
        if not written:
            reasons = list(made.failures.values()) + list(failures.values())
            first = reasons[0] if reasons else "nothing to identify"
            raise InputError(f"no event of campaign seed {task.campaign_seed} could be identified ({first})")
        identified = {p.name.removesuffix(".identify.nc") for p in written}
        events = [f for f in made.files if f.stem in identified]
        results = sorted(written, key=lambda p: p.name)
        events = sorted(events, key=lambda p: p.name)
        metrics = _flatten_scores(campaign_recovery(events, results))
        # The campaign model on the same windows (its verdict needs enough data: see PooledSINDy.min_blocks).
        from vivbench.models.campaign import PooledSINDy
        from vivbench.models.varying import VaryingCoefficientSINDy
        from vivbench.analysis.pool import pool_results
        from vivbench.io.campaign_model import write_campaign_regimes
        from vivbench.validate.campaign_model import campaign_model_recovery

        from vivbench.io.campaign_model import MODEL_NAME

        model = (VaryingCoefficientSINDy if task.campaign_model == "varying" else PooledSINDy)(seed=task.campaign_seed)
        pooled = write_campaign_regimes(pool_results(results, model), root / "identify")
        # the verdicts of a varying model are evaluated by the model itself, which validate loads from its file
        model.save(root / "identify" / MODEL_NAME)
        ps = campaign_model_recovery(events, pooled, results)
        metrics.update({f"campaign_model_{k}": float(ps[k]) for k in ("coverage", "accuracy_all", "accuracy_identifiable",
                                                               "rhs_median_rel_error_active",
                                                               "rhs_error_true_AU_median_active",
                                                               "rhs_error_true_AU_energy")})
    except Exception as exc:
        # Temporary paths differ from run to run; the table must not.
        message = error_line(exc).replace(str(root), "<campaign>")
        raise CampaignFailed(message) from None
    finally:
        if task.keep_dir is None:
            shutil.rmtree(root, ignore_errors=True)
    return {"events_failed": n_failed, **metrics}


# ----------------------------------------------------------------------- run


@dataclass(frozen=True)
class SweepResult:
    """What a call of :func:`run_sweep` did.

    Attributes
    ----------
    table : ``OUT/sweep.csv``, one row per task, sorted by task id
    summary : ``OUT/summary.json``
    figures : the recovery figures written
    n_tasks : tasks in the sweep
    computed : task ids computed by this call
    resumed : task ids found finished in the journal and not recomputed
    failures : task id -> one-line error (these tasks are retried by the next call)
    repaired_lines : corrupt or half-written journal lines dropped on start
    """

    table: Path
    summary: Path
    figures: tuple[Path, ...]
    n_tasks: int
    computed: tuple[int, ...]
    resumed: tuple[int, ...]
    failures: dict[int, str]
    repaired_lines: int


def _exclusive(out: Path):
    # Two sweeps writing one journal would interleave their lines.
    return exclusive_directory(out, ".sweep.lock", "sweep")


def _check_config_record(out: Path, config: SweepConfig) -> None:
    check_record(out / "sweep_config.json", config.fingerprint(), config.to_dict(),
                 "this directory holds the results of a different sweep configuration; use another --out (or "
                 "delete the directory to start over)")


def run_sweep(config: SweepConfig, out_dir: str | Path, *, workers: int = 1, scheduler: str | None = None,
              keep_files: bool = False, progress: Callable[[int, int], None] | None = None) -> SweepResult:
    """Run (or resume) a sweep and write its table, figures and summary.

    Parameters
    ----------
    config : SweepConfig
    out_dir : output directory. It holds ``sweep_config.json`` (the sweep it
        belongs to: another configuration is refused), the journal
        ``sweep.jsonl``, ``sweep.csv``, ``recovery_vs_noise.png``,
        ``recovery_vs_turbulence.png`` and ``summary.json``.
    workers : local worker processes (1: this process), when ``scheduler`` is None
    scheduler : None, ``"local:N"`` (a dask LocalCluster) or a dask scheduler address
    keep_files : keep each campaign and its identification results under
        ``OUT/files/t<task_id>/`` (with a remote cluster: a path the workers share)
    progress : optional ``progress(n_done, n_total)``, called once on start
        (with the tasks found finished) and after every task

    Returns
    -------
    SweepResult
        The numbers in the table do not depend on ``workers``, ``scheduler``
        or on how often the sweep was interrupted and resumed.
    """

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kind, _ = parse_scheduler(scheduler)
    with _exclusive(out):
        _check_config_record(out, config)
        journal = out / "sweep.jsonl"
        tasks = sweep_tasks(config)
        done, repaired = journal_load(journal, n_tasks=len(tasks), columns=COLUMNS)
        work = out / ".work"
        shutil.rmtree(work, ignore_errors=True)  # temporary campaigns of a run that was killed
        # Workers of a remote cluster may not see OUT: they use their own temporary directory.
        work_root = str(work) if kind != "address" else None
        pending = [dataclasses.replace(t, work_root=work_root,
                                       keep_dir=str(out / "files" / f"t{t.task_id:05d}") if keep_files else None)
                   for t in tasks if t.task_id not in done]
        resumed = tuple(sorted(done))
        table = out / "sweep.csv"
        write_table(table, done, COLUMNS)
        if progress is not None:
            progress(len(done), len(tasks))
        computed, failures = [], {}
        try:
            # closing(): an interrupt must cancel the queued tasks now, not when the traceback is freed.
            with closing(run_tasks(run_sweep_task, pending, workers=workers, scheduler=scheduler)) as outcomes:
                for outcome in outcomes:
                    task = pending[outcome.index]
                    row = {**task.describe(), **{c: float("nan") for c in METRIC_COLUMNS}, "error": ""}
                    if outcome.ok:
                        row.update(outcome.value)
                    else:
                        row["error"] = outcome.error
                        failures[task.task_id] = outcome.error
                    journal_append(journal, task.task_id, outcome.ok, row)
                    done[task.task_id] = row
                    computed.append(task.task_id)
                    write_table(table, done, COLUMNS)
                    if progress is not None:
                        progress(len(done), len(tasks))
        finally:
            # After closing the runner no task of this run is still writing here.
            shutil.rmtree(work, ignore_errors=True)
        rows = [done[i] for i in sorted(done)]
        figures = (
            plot_recovery(rows, [p for p in ("noise_density", "anemometer_noise") if p in config.varied]
                          or ["noise_density"], out / "recovery_vs_noise.png", varied=config.varied),
            plot_recovery(rows, ["turbulence_intensity"], out / "recovery_vs_turbulence.png", varied=config.varied),
        )
        summary = out / "summary.json"
        with atomic_path(summary) as tmp:
            tmp.write_text(json.dumps(sweep_summary(rows, config.varied, len(tasks)), indent=1) + "\n")
    return SweepResult(table=table, summary=summary, figures=figures, n_tasks=len(tasks), computed=tuple(computed),
                       resumed=resumed, failures=failures, repaired_lines=repaired)
