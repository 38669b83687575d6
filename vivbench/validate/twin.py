"""A synthetic twin of a campaign: how far its identification can be trusted (docs/field_workflow.md).

The twin mirrors a campaign (:mod:`vivbench.validate.twin_mirror`: sections, rates, events and
their measured mean wind and yaw, turbulence intensity, noise floor, anemometer layout), takes the
bridge's structural properties from a small TOML file, draws its aerodynamics from the field run's
campaign model within its bands (:mod:`vivbench.validate.twin_aero`) and what the records cannot
tell from stated priors (:mod:`vivbench.validate.twin_nuisance`: the errors in the wind, buffeting,
a yaw effect). Each of ``n_draws`` draws generates such a campaign, runs the chain with the field
run's own settings (:mod:`vivbench.validate.twin_chain`) and scores the campaign model against the
draw's truth. The spread over draws is the expected recovery on this bridge: the median of each
figure, its 90 % range for one more campaign (a normal-theory prediction interval over the draws,
of the logarithm for the errors; honest with few draws) and the draws' 5th to 95th percentiles.
A share of flags right of 1 in every draw gives a range of 1, which says only that no twin saw a
failure; so the verdict's promise is also counted over the draws (:func:`twin_promise`): on how
many draws with enough flags it was tested and broken, and the one-sided 95 % upper bound
(Clopper-Pearson) of the chance that a campaign like this one breaks it.

Seeds: draw d uses ``SeedSequence(seed, spawn_key=(d,))``; its first child draws the aerodynamics,
the last the nuisances (both redrawn from their streams, up to :data:`AERO_TRIES` times, while an
event's averaged truth grows without bound and cannot be generated, or drives the deck beyond the
accelerations the identification accepts), the others the events. One
task is one draw; finished draws are journalled (``OUT/twin.jsonl``), so a run stopped part-way
keeps them and the next run resumes; ``OUT/twin.json`` and ``OUT/twin.md`` are rewritten
atomically from the journal alone (no wall times), so the same inputs and seed give the same bytes
whatever the worker count.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from vivbench.core.errors import InputError, error_line
from vivbench.core.lock import exclusive_directory
from vivbench.io.event import list_events, write_event
from vivbench.io.netcdf import atomic_path
from vivbench.io.quality import check_acc_magnitude
from vivbench.io.result import list_results
from vivbench.models.campaign_files import load_campaign_model
from vivbench.synth.event import generate_event
from vivbench.validate.journal import check_record, counting_progress, run_journalled, task_directory
from vivbench.validate.journal import load as journal_load
from vivbench.validate.study_report import PROMISE_MIN_FLAGS, PROMISE_SHARE
from vivbench.validate.twin_aero import draw_aero
from vivbench.validate.twin_chain import (TWIN_METRICS, PoolSettings, chain_scores, identify_config_from_json,
                                          pool_method, pool_settings, run_chain)
from vivbench.validate.twin_mirror import (CampaignMirror, TwinBridge, measure_campaign, mirror_generator,
                                           mirror_specs, mirror_structure, read_bridge)
from vivbench.validate.twin_nuisance import NuisancePriors, apply_nuisances, draw_nuisances

__all__ = ["AERO_TRIES", "TwinConfig", "TwinTask", "TwinResult", "twin_inputs", "run_twin", "run_twin_task", "twin_summary",
           "twin_promise", "twin_markdown", "read_twin", "TWIN_FILE", "METRIC_NAMES"]

#: The summary file of a twin's output directory.
TWIN_FILE = "twin.json"
#: Readable names of :data:`~vivbench.validate.twin_chain.TWIN_METRICS`.
METRIC_NAMES = {
    "coverage": "share of window-equations flagged identifiable",
    "flagged_right_share": "share of flagged window-equations with the true regime",
    "n_flagged": "flagged window-equations",
    "rhs_error_true_AU_energy": "dA/dt error, energy-weighted (relative RMS over all samples)",
    "rhs_error_true_AU_median": "dA/dt error, median over windows (relative RMS)",
    "curve_error_linear": "curve error of the net linear coefficient (reference section)",
    "curve_error_total": "curve error of all orders (reference section)",
    "curve_error_energy": "curve error, energy-weighted",
}
_COLUMNS = ("task_id", "draw", "scores")


@dataclass(frozen=True, kw_only=True)
class TwinConfig:
    """What a twin runs.

    Attributes
    ----------
    n_draws : twin campaigns (each a new draw of the aerodynamics, the nuisances, wind turbulence and noise)
    seed : root seed
    knot_step : s; spacing of the wind scripts' knots
    max_events : mirror only the first events (None: all); for quick checks, recorded in the outputs
    priors : NuisancePriors of what the records cannot tell (the generator family's by default), or None
        to fix them at the generator's defaults (tributary-averaged felt wind, buffeting_w 0.6,
        buffeting_u 0, no yaw effect)
    """

    n_draws: int = 5
    seed: int = 0
    knot_step: float = 120.0
    max_events: int | None = None
    priors: NuisancePriors | None = NuisancePriors()

    def __post_init__(self) -> None:
        if isinstance(self.n_draws, bool) or not isinstance(self.n_draws, int) or not 1 <= self.n_draws <= 1000:
            raise InputError(f"n_draws must be an integer from 1 to 1000; got {self.n_draws!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise InputError(f"seed must be an integer >= 0; got {self.seed!r}")
        if not (isinstance(self.knot_step, (int, float)) and 10.0 <= self.knot_step <= 1800.0):
            raise InputError(f"knot_step must be 10-1800 s; got {self.knot_step!r}")
        if self.max_events is not None and not (isinstance(self.max_events, int) and self.max_events >= 1):
            raise InputError(f"max_events must be an integer >= 1 or None; got {self.max_events!r}")
        if self.priors is not None and not isinstance(self.priors, NuisancePriors):
            raise InputError(f"priors must be a NuisancePriors or None; got {type(self.priors).__name__}")


@dataclass(frozen=True, kw_only=True)
class TwinTask:
    """One twin draw: everything a worker needs."""

    draw: int
    seed: int
    mirror: CampaignMirror
    bridge: TwinBridge
    pool: PoolSettings
    wind_range: tuple[float, float]
    priors: NuisancePriors | None = None
    work_root: str | None = None


@dataclass(frozen=True)
class TwinResult:
    """What :func:`run_twin` did: ``summary`` (twin.json), ``page`` (twin.md), draws computed and resumed,
    failures (draw -> one-line error, retried by the next run)."""

    summary: Path
    page: Path
    computed: tuple[int, ...]
    resumed: tuple[int, ...]
    failures: dict[int, str]


def twin_inputs(campaign_dir, results_dir, *, max_events: int | None = None) -> tuple[list[Path], list[Path]]:
    """The campaign's event files and their results (paired by event id, in event-id order)."""
    events = list_events(campaign_dir)
    results = list_results(results_dir)
    if not events:
        raise InputError(f"{campaign_dir}: no event files (<event_id>.nc)")
    if not results:
        raise InputError(f"{results_dir}: no identification results (<event_id>.identify.nc); run vivbench identify")
    ids = {p.name.removesuffix(".identify.nc") for p in results}
    events = [e for e in sorted(events, key=lambda p: p.name) if e.stem in ids]
    if max_events is not None:
        events = events[:max_events]
    keep = {e.stem for e in events}
    return events, [r for r in sorted(results, key=lambda p: p.name) if r.name.removesuffix(".identify.nc") in keep]


#: Draws of the aerodynamics tried per twin draw before it fails: a draw whose averaged truth grows without bound
#: in some event (a large nonlinear term where Y1 < 0) cannot be generated and is redrawn, as is one whose deck
#: accelerates beyond what the identification accepts.
AERO_TRIES = 5


def _plausible(event):
    """The generated event, or InputError (the draw is redrawn) when its deck accelerates more than any deck does:
    the identification refuses such records (:func:`vivbench.io.quality.check_acc_magnitude`), and a bridge whose
    aerodynamics drive it there could not have given the measured campaign."""
    check_acc_magnitude(event["accel"]["acc"].values, where="twin event",
                        labels=[str(s) for s in event["accel"]["section"].values])
    return event


def _twin_campaign(task: TwinTask, model, structure, children, root: Path):
    """The twin's aerodynamics, nuisances and event files: redrawn (from their streams) while an event cannot be
    generated."""
    rng, nuisance_rng = np.random.default_rng(children[0]), np.random.default_rng(children[-1])
    yaws = np.concatenate([e.yaws for e in task.mirror.events])
    specs = mirror_specs(task.mirror)
    for attempt in range(1, AERO_TRIES + 1):
        nuisances = None if task.priors is None else draw_nuisances(task.priors, yaws, nuisance_rng)
        e_mix = "both" if nuisances is None or not task.mirror.amplitude_scale else nuisances.e_mix
        aero, misfit = draw_aero(model, structure, task.wind_range, rng, e_mix=e_mix,
                                 amplitude=task.mirror.amplitude_scale)
        generator = mirror_generator(task.mirror, structure, aero)
        if nuisances is not None:
            nuisances = dataclasses.replace(nuisances, e_mix=e_mix)
            generator = apply_nuisances(generator, nuisances)
        try:
            files = [write_event(_plausible(generate_event(spec, generator, seed, campaign_seed=task.seed)),
                                 root / "campaign" / f"{spec.event_id}.nc")
                     for spec, seed in zip(specs, children[1:len(specs) + 1])]
            return aero, misfit, nuisances, attempt, files
        except InputError:
            shutil.rmtree(root / "campaign", ignore_errors=True)
            if attempt == AERO_TRIES:
                raise


def run_twin_task(task: TwinTask) -> dict[str, Any]:
    """Generate one twin campaign, run the chain on it and score it; runs in a worker."""
    root_seed = np.random.SeedSequence(task.seed, spawn_key=(task.draw,))
    children = root_seed.spawn(len(task.mirror.events) + 2)
    model = load_campaign_model(task.pool.model_path)
    structure = mirror_structure(task.mirror, task.bridge)
    root = task_directory(task.work_root, f"twin{task.draw:04d}-")
    try:
        aero, misfit, nuisances, tries, files = _twin_campaign(task, model, structure, children, root)
        identify = identify_config_from_json(task.mirror.identify_json)
        fitted, records, truths, windows = run_chain(files, root / "identify", identify, pool_method(task.pool),
                                                     wind_smoothing_s=task.pool.wind_smoothing_s)
        scores = chain_scores(fitted, records, truths, windows, tau=identify.tau)
        n_events = len(records)
    except Exception as exc:
        raise RuntimeError(error_line(exc).replace(str(root), "<draw>")) from None
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return {"draw": task.draw, "scores": scores, "n_events": n_events, "aero_misfit": misfit, "aero_tries": tries,
            "aero": {"Y1": dataclasses.asdict(aero.Y1), "C_L": dataclasses.asdict(aero.C_L),
                     "e1": dataclasses.asdict(aero.e1), "e2": dataclasses.asdict(aero.e2)},
            "nuisances": None if nuisances is None else nuisances.to_dict()}


def _spread(values: Sequence[float], bounds: tuple[float, float], log: bool) -> dict[str, float]:
    """Median, 5th-95th percentiles of the draws, and the 90 % prediction range of one more campaign.

    The prediction range is the normal-theory interval mean +- t(0.95, K - 1) s sqrt(1 + 1/K) of K draws,
    on the logarithm of the figure when ``log`` (relative errors, positive and skewed: the range is then
    a factor either side of the geometric mean) and clipped to the figure's bounds: with few draws the
    draws' own percentiles understate where another campaign's figure may fall; with many the two agree.
    """
    from scipy.stats import t as student_t

    x = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    out = {"median": math.nan, "low": math.nan, "high": math.nan, "predict_low": math.nan, "predict_high": math.nan,
           "n": int(x.size)}
    if x.size == 0:
        return out
    lo, med, hi = np.percentile(x, [5.0, 50.0, 95.0])
    out.update(median=float(med), low=float(lo), high=float(hi))
    if x.size >= 2:
        log = log and bool(np.all(x > 0))
        y = np.log(x) if log else x
        half = float(student_t.ppf(0.95, y.size - 1) * np.std(y, ddof=1) * math.sqrt(1.0 + 1.0 / y.size))
        a, b = np.mean(y) - half, np.mean(y) + half
        a, b = (math.exp(a), math.exp(b)) if log else (a, b)
        out.update(predict_low=float(max(a, bounds[0])), predict_high=float(min(b, bounds[1])))
    return out


#: Figures that are shares (a linear range within [0, 1]) or counts; the others are relative errors (log range).
_BOUNDS = {"coverage": (0.0, 1.0), "flagged_right_share": (0.0, 1.0), "n_flagged": (0.0, math.inf)}


def twin_promise(scores: Sequence[dict]) -> dict[str, Any]:
    """The verdict's promise over twin draws: at least :data:`PROMISE_SHARE` of at least :data:`PROMISE_MIN_FLAGS`
    flagged window-equations right.

    Parameters
    ----------
    scores : sequence of dict, each draw's figures (``n_flagged``, ``flagged_right_share``)

    Returns
    -------
    dict
        ``tested`` (draws with enough flags), ``broken`` (those below the share) and ``broken_upper``: the
        one-sided 95 % Clopper-Pearson upper bound of the chance that a campaign like the twins breaks the
        promise (``1 - 0.05 ** (1 / tested)`` when none broke it; NaN when none was tested).
    """
    from scipy.stats import beta

    shares = [float(s.get("flagged_right_share", math.nan)) for s in scores
              if float(s.get("n_flagged", 0) or 0) >= PROMISE_MIN_FLAGS]
    shares = [x for x in shares if math.isfinite(x)]
    n, k = len(shares), sum(x < PROMISE_SHARE for x in shares)
    upper = math.nan if n == 0 else (1.0 if k == n else float(beta.ppf(0.95, k + 1, n - k)))
    return {"tested": n, "broken": int(k), "broken_upper": upper}


def twin_summary(config: dict, mirror: CampaignMirror, rows: dict[int, dict], failed: dict[int, str]) -> dict:
    """The content of ``twin.json``: the inputs, each draw's scores, the failed draws' errors and the expected
    recovery."""
    draws = [rows[d] for d in sorted(rows)]
    expected = {m: _spread([r["scores"][m] for r in draws], _BOUNDS.get(m, (0.0, math.inf)), log=m not in _BOUNDS)
                for m in TWIN_METRICS}
    return {
        "format": "vivbench-twin", "format_version": 1, "config": config,
        "mirror": {"sections": list(mirror.sections), "n_events": len(mirror.events),
                   "durations_s": [e.duration for e in mirror.events], "wind_rate_hz": mirror.wind_rate,
                   "accel_rate_hz": mirror.accel_rate, "turbulence_intensity": mirror.turbulence_intensity,
                   "section_offset": mirror.section_offset, "noise_density_ug_rthz": mirror.noise_density,
                   "anemometer_offset_m": mirror.anemometer_offset, "frequency_hz": mirror.frequency,
                   "mode_shape_measured": list(mirror.mode_shape),
                   "anemometer_positions_m": list(mirror.anemometer_positions), "span_length_m": mirror.span_length,
                   "wind_rule": mirror.wind_rule, "amplitude_scale_m": list(mirror.amplitude_scale)},
        "draws": draws, "failed": sorted(int(d) for d in failed),
        "errors": {str(d): failed[d] for d in sorted(failed)}, "expected": expected,
        "promise": twin_promise([r["scores"] for r in draws]),
        "range": "low/high: 5th and 95th percentiles of the draws; predict_low/predict_high: 90 % prediction "
                 "range of one more campaign, mean +- t(0.95, K-1) s sqrt(1 + 1/K) over K draws (of the "
                 "logarithm for the errors)",
    }


def _fmt(x: float) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.3g}"


def twin_markdown(summary: dict) -> str:
    """``twin.md``: the expected recovery as a table, and what was mirrored and assumed."""
    m, cfg = summary["mirror"], summary["config"]
    n = len(summary["draws"])
    lines = [
        "# Synthetic twin: expected recovery on this campaign", "",
        f"{n} twin draw{'s' if n != 1 else ''} (seed {cfg['seed']}) of {m['n_events']} events, sections "
        f"{', '.join(m['sections'])}, wind at {m['wind_rate_hz']:g} Hz, acceleration at {m['accel_rate_hz']:g} Hz, "
        f"turbulence intensity {m['turbulence_intensity']:.3f}, noise floor {m['noise_density_ug_rthz']:.3g} "
        f"micro-g/sqrt(Hz), mode {m['frequency_hz']:.4g} Hz." + (" Failed draws: "
                                                                   + ", ".join(map(str, summary["failed"])) + "."
                                                                   if summary["failed"] else ""), "",
        "| figure | median | 90 % range of a campaign | 5th-95th percentile of draws | draws |",
        "|---|---|---|---|---|",
    ]
    for key, s in summary["expected"].items():
        lines.append(f"| {METRIC_NAMES[key]} | {_fmt(s['median'])} | {_fmt(s['predict_low'])} - "
                     f"{_fmt(s['predict_high'])} | {_fmt(s['low'])} - {_fmt(s['high'])} | {s['n']} |")
    p = summary.get("promise")
    if p is not None:
        lines += ["", (f"The verdict's promise (at least {PROMISE_SHARE * 100:.0f} % of at least {PROMISE_MIN_FLAGS} "
                       f"flagged window-equations right) was tested on {p['tested']} twin draw{'s' if p['tested'] != 1 else ''}"
                       f" and broken on {p['broken']}: a campaign like this one breaks it with a chance of at most "
                       f"{p['broken_upper'] * 100:.0f} % (one-sided 95 % bound)." if p["tested"] else
                       f"No twin draw flagged {PROMISE_MIN_FLAGS} window-equations or more: the verdict's promise "
                       "was not tested.")]
    layout = (f"anemometers at {', '.join(f'{x:g}' for x in m['anemometer_positions_m'])} m of "
              f"{m['span_length_m']:g} m ({m['wind_rule']} rule)" if m.get("anemometer_positions_m")
              else "one anemometer per section")
    priors = cfg.get("priors")
    if priors is None:
        drawn = ("Fixed at the generator's defaults: the tributary-averaged wind the deck feels, buffeting, no yaw "
                 "effect.")
    else:
        drawn = ("Drawn per twin from stated priors (the generator family's): the wind the deck feels (tributary "
                 f"average, or smooth with point turbulence at the anemometers with probability "
                 f"{priors['smooth_share']:g}, its time scale log-uniform {priors['point_timescale_s'][0]:g}-"
                 f"{priors['point_timescale_s'][1]:g} s), buffeting_w U({priors['buffeting_w'][0]:g}, "
                 f"{priors['buffeting_w'][1]:g}), buffeting_u U({priors['buffeting_u'][0]:g}, "
                 f"{priors['buffeting_u'][1]:g}), "
                 + ("a yaw effect on Y1 and C_L (absent, or one of four shapes) along the measured yaws, Y1 and C_L "
                    "divided by its mean over them" if priors["yaw_effect"] else "no yaw effect")
                 + _e_mix_text(priors.get("e_mix_shares", (1.0, 0.0, 0.0))))
    lines += ["", "Mirrored: sections, rates, events (number, start times, durations), each event's measured mean "
              "wind and yaw (knots every " f"{cfg['knot_step']:g} s), turbulence intensity, sections' wind spread, "
              f"noise floor, {layout}, the identification's and the campaign model's settings. Assumed: the bridge "
              "file's structural properties; aerodynamic functions of the generator's shapes fitted to the campaign "
              "model's curves drawn within their bands; the generator's defaults for the Strouhal number and the "
              "anemometers' own errors. " + drawn, ""]
    rows = [r for r in summary["draws"] if r.get("nuisances")]
    if rows:
        lines += ["| draw | felt wind | point time scale, s | buffeting_w | buffeting_u | yaw effect | mean yaw factor "
                  "| amplitude limited by |", "|---|---|---|---|---|---|---|---|"]
        for r in rows:
            n_ = r["nuisances"]
            lines.append(f"| {r['draw']} | {n_['felt_wind']} | {_fmt(n_['point_timescale_s'])} | "
                         f"{_fmt(n_['buffeting_w'])} | {_fmt(n_['buffeting_u'])} | {n_['yaw_shape']} | "
                         f"{_fmt(n_['yaw_mean_factor'])} | {_E_MIX_NAMES[n_.get('e_mix', 'both')]} |")
        lines.append("")
    lines += ["The 90 % range of a campaign is where one more campaign's figure falls with 90 % probability if the "
              "draws' figures (the logarithms of the errors) are normal (mean +- t s sqrt(1 + 1/K)); with few draws "
              "it is wide, as it should be.", ""]
    return "\n".join(lines)


#: How the twin's page names each ``e_mix``.
_E_MIX_NAMES = {"both": "as the model splits it", "e1_only": "A^2 alone", "e2_only": "A^3 alone"}


def _e_mix_text(shares) -> str:
    both, e1, e2 = (float(x) for x in shares)
    if both == 1.0:
        return "; the nonlinear damping split between A^2 and A^3 as the campaign model splits it."
    return (f"; the nonlinear damping split between A^2 and A^3 as the campaign model splits it with probability "
            f"{both:g}, else carried by A^2 alone ({e1:g}) or A^3 alone ({e2:g}), equal to the model's at each "
            "section's 99th percentile of the measured amplitude.")


def read_twin(directory) -> dict:
    """The ``twin.json`` of a twin's output directory (InputError naming the file when absent or unreadable)."""
    path = Path(directory) / TWIN_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such file; run vivbench twin --out {directory}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != "vivbench-twin":
        raise InputError(f"{path}: not a twin summary (format vivbench-twin)")
    return data


def run_twin(campaign_dir, results_dir, bridge, out_dir, *, config: TwinConfig = TwinConfig(), model_dir=None,
             workers: int = 1, progress: Callable[[int, int], None] | None = None) -> TwinResult:
    """Run (or resume) a twin and write ``twin.json`` and ``twin.md`` (module docstring).

    Parameters
    ----------
    campaign_dir : the campaign's event files
    results_dir : their identification results
    bridge : path of the bridge file (:func:`vivbench.validate.twin_mirror.read_bridge`) or a TwinBridge
    out_dir : output directory (also holds ``twin_config.json`` and the journal ``twin.jsonl``)
    config : TwinConfig
    model_dir : where ``vivbench pool`` wrote its files (default ``results_dir``)
    workers : local worker processes (1: this process); the files do not depend on it
    progress : optional ``progress(n_done, n_total)``
    """
    bridge = bridge if isinstance(bridge, TwinBridge) else read_bridge(bridge)
    events, results = twin_inputs(campaign_dir, results_dir, max_events=config.max_events)
    mirror = measure_campaign(events, results, knot_step=config.knot_step)
    mirror_structure(mirror, bridge)  # bad properties fail here, before any draw
    settings = pool_settings(model_dir if model_dir is not None else results_dir)
    speeds = np.concatenate([e.speeds for e in mirror.events])
    wind_range = (float(max(np.min(speeds), 0.5)), float(max(np.max(speeds), np.min(speeds) + 1.0)))
    cfg = {"n_draws": config.n_draws, "seed": config.seed, "knot_step": config.knot_step,
           "max_events": config.max_events, "priors": None if config.priors is None else config.priors.to_dict(), "bridge": {k: v for k, v in dataclasses.asdict(bridge).items()
                                                       if k != "source"},
           "pool": settings.to_dict(), "identify": json.loads(mirror.identify_json), "wind_range": list(wind_range)}
    fingerprint = hashlib.sha256(json.dumps({"cfg": {k: v for k, v in cfg.items() if k != "n_draws"},
                                             "mirror": mirror.to_dict()}, sort_keys=True).encode()).hexdigest()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with exclusive_directory(out, ".twin.lock", "twin"):
        check_record(out / "twin_config.json", fingerprint, {k: v for k, v in cfg.items() if k != "n_draws"},
                     "this directory holds a twin of another campaign, bridge, settings or seed; use another --out "
                     "(or delete the directory to start over)")
        journal = out / "twin.jsonl"
        done, _ = journal_load(journal, n_tasks=1000, columns=_COLUMNS)
        done = {d: r for d, r in done.items() if d < config.n_draws}
        resumed = tuple(sorted(done))
        work = out / ".work"
        shutil.rmtree(work, ignore_errors=True)
        pending = [TwinTask(draw=d, seed=config.seed, mirror=mirror, bridge=bridge, pool=settings,
                            wind_range=wind_range, priors=config.priors, work_root=str(work))
                   for d in range(config.n_draws) if d not in done]
        if progress is not None:
            progress(len(resumed), config.n_draws)
        try:
            computed, failures = run_journalled(
                run_twin_task, pending, journal, done, task_id=lambda t: t.draw,
                failed_row=lambda t: {"draw": t.draw, "scores": {}}, workers=workers,
                progress=None if progress is None else counting_progress(progress, len(resumed), config.n_draws))
        finally:
            shutil.rmtree(work, ignore_errors=True)
        rows = {d: {k: v for k, v in r.items() if k != "task_id"} for d, r in done.items()}
        summary = twin_summary(cfg, mirror, rows, failures)
        summary_path, page = out / TWIN_FILE, out / "twin.md"
        with atomic_path(summary_path) as tmp:
            tmp.write_text(json.dumps(summary, indent=1, sort_keys=True, allow_nan=True) + "\n", encoding="utf-8")
        with atomic_path(page) as tmp:
            tmp.write_text(twin_markdown(summary), encoding="utf-8")
    return TwinResult(summary=summary_path, page=page, computed=tuple(sorted(computed)), resumed=resumed,
                      failures=failures)
