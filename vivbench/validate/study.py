"""Studies over the generator family: every draw generated, identified, and every method fitted and scored.

A study runs draws of one split of the generator family (:mod:`vivbench.synth.family`):
for each draw it generates the campaign, identifies every event (as ``vivbench identify``
does, with :class:`~vivbench.analysis.identify.IdentifyConfig`'s defaults unless given), then
fits each method on the identified records and scores it against the truth with
:func:`~vivbench.validate.methods.score_fitted` on the identification's windows. Beside the
standard scores each row holds the draw's labels (what was drawn), the number of flagged
window-equations (``n_flagged``), the share of them whose regime is right
(``flagged_right_share``, the verdict's promise is >= 0.95) and, on every draw,
``self_excited_flags``: flagged window-equations whose model regime is 2, 3 or 4
(self-excitation claimed; on forced-only draws every one is wrong).

One task is one draw; its seeds are the family's, so a task gives the same numbers wherever
it runs (this process, local processes, a dask cluster: :func:`vivbench.core.parallel.run_tasks`).
Finished draws are journalled (``OUT/study.jsonl``, :mod:`vivbench.validate.journal`): a
study stopped part-way keeps them, and running it again resumes; a failed draw is retried.
``OUT/study.csv`` (one row per draw and method), ``OUT/summary.json`` and ``OUT/study.md``
(:mod:`vivbench.validate.study_report`) are rewritten atomically after the run, from the
journal alone, so the same draws give the same bytes. Wall times are kept in the journal
only (they change from run to run).

The ``greybox`` method (:class:`vivbench.validate.greybox_method.GreyBoxMethod`) is fitted on
each draw with that draw's structural properties
(:func:`~vivbench.validate.greybox_method.structural_properties`: mass, deck depth, frequency,
structural damping, air density, mode shape, tributary lengths; never the aerodynamics), as an
engineer takes them from design documents, and with the default campaign model (``varying``)
as its warm start and verdict reference; when ``varying`` is also studied, its fitted model is
used (the methods are fitted in an order that puts ``varying`` first).

``max_events`` and ``max_duration`` shrink every campaign (for quick checks); a capped
study's outputs say so on their first lines. ``wind_source="truth"`` fits every method on
records whose wind is the truth's own (an oracle): run beside the same study on the measured
wind, it tells how much of a method's error and of its verdict's failures comes from the errors
in the wind rather than from its model class. ``amplitude_source="truth"`` also replaces each
record's amplitude and dA/dt by the truth's averaged ones; with both, what is left is the error of
the method's model class alone.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import math
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vivbench.analysis.identify import IdentifyConfig, identify_files
from vivbench.core.errors import InputError, error_line
from vivbench.models.protocol import model_change_inputs, model_evidence
from vivbench.core.lock import exclusive_directory
from vivbench.core.parallel import parse_scheduler
from vivbench.core.regime import DEFAULT_TAU
from vivbench.io.netcdf import atomic_path
from vivbench.regimes.model import model_window_regimes
from vivbench.synth.family import SPLITS, draw_bridge
from vivbench.synth.campaign import generate_campaign
from vivbench.synth.config import WindConfig
from vivbench.validate.journal import check_record
from vivbench.validate.journal import format_value
from vivbench.validate.journal import counting_progress, run_journalled, task_directory
from vivbench.validate.journal import load as journal_load
from vivbench.validate.methods import BUILTIN_METHODS, SCORE_KEYS, check_method_spec, fit_method, resolve_method
from vivbench.validate.methods import curve_scores, score_fitted, scoring_inputs
from vivbench.validate.recovery import record_with_truth_amplitude, record_with_truth_wind
from vivbench.validate.study_report import LABEL_COLUMNS, study_markdown, study_summary

__all__ = ["AMPLITUDE_SOURCES", "DRAW_METHODS", "METHOD_ALIASES", "STUDY_COLUMNS", "WIND_SOURCES", "StudyConfig",
           "StudyTask", "StudyResult", "check_draws",
           "method_spec", "parse_draws", "run_study", "run_study_task", "study_method", "study_tasks"]

#: Short names of the study's methods that are not :func:`resolve_method` names.
METHOD_ALIASES: dict[str, str] = {}
#: Study methods built from each draw's structural properties (not :func:`resolve_method` names).
DRAW_METHODS = ("greybox",)
#: What a study's methods are fitted on: the measured wind, or the truth's (an oracle).
WIND_SOURCES = ("measured", "truth")
#: What the methods' amplitude and dA/dt are (StudyConfig.amplitude_source).
AMPLITUDE_SOURCES = ("measured", "truth")
#: Per-method columns beside the standard scores (fit time left out: it changes from run to run).
_FLAG_COLUMNS = ("n_flagged", "flagged_right_share", "self_excited_flags", "chosen", "confidence_set", "dynamics_shown", "stationary",
                 "curve_error_energy_yaw_free", "change_p_value", "change_detected", "change_index")
_SCORES = tuple(k for k in SCORE_KEYS if k != "fit_time_s")
#: Columns of ``study.csv``: one row per draw and method.
STUDY_COLUMNS = ("split", "draw", "method", "campaign_seed", "n_events", "events_failed", *LABEL_COLUMNS,
                 "yaw_factor_range", *_SCORES, *_FLAG_COLUMNS, "error")
_JOURNAL_COLUMNS = ("task_id", "draw", "methods")
_MAX_DRAW = 2**31


def method_spec(name: str) -> str:
    """The :func:`resolve_method` spec of a study method name (the same name: study names are method names;
    a :data:`DRAW_METHODS` name is its own)."""
    if name in DRAW_METHODS:
        return name
    spec = name if name in BUILTIN_METHODS else METHOD_ALIASES.get(name, name)
    return check_method_spec(spec)


def parse_draws(text: str) -> tuple[int, ...]:
    """``"0-29"``, ``"3"`` or ``"0-3,10,12-13"`` -> sorted draw numbers without repeats."""
    out: set[int] = set()
    for part in str(text).split(","):
        lo, sep, hi = part.strip().partition("-")
        try:
            a = int(lo)
            b = int(hi) if sep else a
        except ValueError:
            raise InputError(f"draws must be N, N-M or a comma-separated list of them (from 0); got {text!r}") from None
        if not 0 <= a <= b < _MAX_DRAW:
            raise InputError(f"draws must be N, N-M or a comma-separated list of them (from 0); got {text!r}")
        out.update(range(a, b + 1))
    return tuple(sorted(out))


def check_draws(draws) -> tuple[int, ...]:
    """Draw numbers as a tuple of ints; InputError unless distinct, >= 0 and increasing."""
    out = tuple(int(d) for d in draws)
    if not out or list(out) != sorted(set(out)) or out[0] < 0:
        raise InputError(f"draws must be distinct draw numbers >= 0 in increasing order; got {draws!r}")
    return out


@dataclass(frozen=True, kw_only=True)
class StudyConfig:
    """What a study runs.

    Attributes
    ----------
    split : "development" or "evaluation"
    draws : draw numbers, sorted, without repeats
    methods : study method names (built-in method names such as ``pooled`` and ``varying``; ``greybox`` the
        grey-box refit given the draw's structural properties; or ``package.module:factory`` that
        :func:`resolve_method` knows)
    max_events : cap on each campaign's events (None: the draw's)
    max_duration : s; cap on each event's duration (None: the draw's)
    identify : the identification's configuration
    tau : regime threshold (docs/concepts.md (regimes))
    anemometer_span : fractions of the span length, or None; when given, every draw's campaign
        has anemometers there instead of one per section (``WindConfig.anemometer_span``, e.g.
        ``(0.5,)``: one at mid-span), the wind at each section taken from them by ``wind_rule``
    wind_rule : "nearest" or "interpolation" (``WindConfig.wind_rule``)
    wind_source : "measured" (the methods are fitted on the identified records, as a user's are) or
        "truth" (an oracle: each record's wind and yaw replaced by those the truth's dynamics sees,
        :func:`~vivbench.validate.recovery.record_with_truth_wind`; the scores are then those of the
        method with the errors in the wind removed)
    amplitude_source : "measured" (the identified envelopes and the campaign's dA/dt) or "truth" (an
        oracle: each record's amplitude and dA/dt replaced by the truth's averaged ones,
        :func:`~vivbench.validate.recovery.record_with_truth_amplitude`; with ``wind_source="truth"``
        the scores are those of the method's model class alone)
    """

    split: str
    draws: tuple[int, ...]
    methods: tuple[str, ...]
    max_events: int | None = None
    max_duration: float | None = None
    identify: IdentifyConfig = field(default_factory=IdentifyConfig)
    tau: float = DEFAULT_TAU
    anemometer_span: tuple[float, ...] | None = None
    wind_rule: str = "nearest"
    wind_source: str = "measured"
    amplitude_source: str = "measured"

    def __post_init__(self) -> None:
        if self.wind_source not in WIND_SOURCES:
            raise InputError(f"wind_source must be one of {', '.join(WIND_SOURCES)}; got {self.wind_source!r}")
        if self.amplitude_source not in AMPLITUDE_SOURCES:
            raise InputError(f"amplitude_source must be one of {', '.join(AMPLITUDE_SOURCES)}; "
                             f"got {self.amplitude_source!r}")
        if self.anemometer_span is not None or self.wind_rule != "nearest":
            # the generator's own checks (a felt wind that allows fewer anemometers is the family's)
            layout = WindConfig(anemometer_span=self.anemometer_span, wind_rule=self.wind_rule)
            object.__setattr__(self, "anemometer_span", layout.anemometer_span)
        if self.split not in SPLITS:
            raise InputError(f"split must be one of {', '.join(SPLITS)}; got {self.split!r}")
        object.__setattr__(self, "draws", check_draws(self.draws))
        methods = tuple(self.methods)
        if not methods or len(set(methods)) != len(methods):
            raise InputError(f"methods must be one or more distinct names; got {list(methods)}")
        for m in methods:
            method_spec(m)
        object.__setattr__(self, "methods", methods)
        if self.max_events is not None and not (isinstance(self.max_events, int) and self.max_events >= 1):
            raise InputError(f"max_events must be an integer >= 1 or None; got {self.max_events!r}")
        if self.max_duration is not None and not (math.isfinite(self.max_duration) and self.max_duration >= 120.0):
            raise InputError(f"max_duration must be >= 120 s or None; got {self.max_duration!r}")

    @property
    def capped(self) -> bool:
        """True when the campaigns are smaller than the family's draws."""
        return self.max_events is not None or self.max_duration is not None

    def to_dict(self) -> dict[str, Any]:
        """Plain data (the draws included); the anemometer layout only when it is not one per section, the
        wind source only when it is not the measured wind."""
        data = {"split": self.split, "draws": list(self.draws), "methods": list(self.methods),
                "max_events": self.max_events, "max_duration_s": self.max_duration,
                "identify": json.loads(self.identify.to_json()), "tau": self.tau}
        if self.anemometer_span is not None:
            data.update(anemometer_span=list(self.anemometer_span), wind_rule=self.wind_rule)
        if self.wind_source != "measured":
            data.update(wind_source=self.wind_source)
        if self.amplitude_source != "measured":
            data.update(amplitude_source=self.amplitude_source)
        return data

    def fingerprint(self) -> str:
        """SHA-256 of everything but the draws: the draws of one study directory may grow from run to run."""
        data = self.to_dict()
        del data["draws"]
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


@dataclass(frozen=True, kw_only=True)
class StudyTask:
    """One draw of a study: everything a worker needs (the draw's seeds are the family's)."""

    split: str
    draw: int
    methods: tuple[str, ...]
    max_events: int | None
    max_duration: float | None
    identify: IdentifyConfig
    tau: float = DEFAULT_TAU
    work_root: str | None = None
    anemometer_span: tuple[float, ...] | None = None
    wind_rule: str = "nearest"
    wind_source: str = "measured"
    amplitude_source: str = "measured"

    def campaign(self, draw):
        """The draw's (capped) campaign, with this task's anemometers when it places them."""
        campaign = draw.campaign_config(max_events=self.max_events, max_duration=self.max_duration)
        if self.anemometer_span is None:
            return campaign
        gen = campaign.generator
        wind = dataclasses.replace(gen.wind, anemometer_span=self.anemometer_span, wind_rule=self.wind_rule)
        return dataclasses.replace(campaign, generator=dataclasses.replace(gen, wind=wind))


def study_tasks(config: StudyConfig) -> list[StudyTask]:
    """One task per draw, in draw order. Cheap: nothing runs."""
    return [StudyTask(split=config.split, draw=d, methods=config.methods, max_events=config.max_events,
                      max_duration=config.max_duration, identify=config.identify, tau=config.tau,
                      anemometer_span=config.anemometer_span, wind_rule=config.wind_rule,
                      wind_source=config.wind_source, amplitude_source=config.amplitude_source)
            for d in config.draws]


class _FlagRecorder:
    """A fitted model seen through :func:`score_fitted`, keeping each record's window regimes and flags."""

    def __init__(self, fitted, tau: float):
        self._fitted = fitted
        self._tau = tau
        self.regimes: list[np.ndarray] = []
        self.flags: list[np.ndarray] = []
        if callable(getattr(fitted, "identifiable", None)):
            self.identifiable = self._identifiable

    def __getattr__(self, name):
        return getattr(self._fitted, name)

    def window_regimes(self, record, window_start, window_end) -> np.ndarray:
        own = getattr(self._fitted, "window_regimes", None)
        if callable(own):
            r = own(record, window_start, window_end)
        else:  # score_fitted's own rule for a model without window_regimes
            r = model_window_regimes(self._fitted, record, window_start, window_end, tau=self._tau)["regime"]
        r = np.asarray(r, dtype=int)
        self.regimes.append(r)
        return r

    def _identifiable(self, record, window_start, window_end) -> np.ndarray:
        ok = np.asarray(self._fitted.identifiable(record, window_start, window_end), dtype=bool)
        self.flags.append(ok)
        return ok

    def self_excited_flags(self) -> int:
        """Flagged window-equations whose model regime is 2, 3 or 4."""
        if not self.flags:
            return 0
        return int(sum(int(np.sum(ok & (r >= 2))) for r, ok in zip(self.regimes, self.flags)))


def study_method(name: str, draw, fitted: dict | None = None, *, tau: float = DEFAULT_TAU):
    """The method a study fits on one draw's campaign.

    Parameters
    ----------
    name : study method name (:class:`StudyConfig` ``methods``)
    draw : vivbench.synth.family.FamilyDraw
        Only its structure is read, by ``greybox``
        (:func:`~vivbench.validate.greybox_method.structural_properties`).
    fitted : method name -> its fitted model on this draw, so far (``greybox`` takes ``varying``'s
        as its reference when there)
    tau : regime threshold of the grey-box verdict

    Returns
    -------
    method : an object with ``fit(records)``
    """
    if name == "greybox":
        from vivbench.validate.greybox_method import GreyBoxMethod, structural_properties

        reference = (fitted or {}).get("varying", "varying")
        return GreyBoxMethod(structural_properties(draw.config.structure), reference=reference, tau=tau)
    return resolve_method(method_spec(name))


def _fit_order(methods: Sequence[str]) -> list[str]:
    """The methods in the order they are fitted on a draw: those another one reuses first."""
    return sorted(methods, key=lambda m: 0 if m == "varying" else 1)


def _score(method, records, truths, windows, tau: float) -> tuple[dict[str, Any], Any]:
    fitted, seconds = fit_method(method, records)
    seen = _FlagRecorder(fitted, tau)
    scores = score_fitted(seen, records, truths, windows=windows, tau=tau, simulate=False, fit_time_s=seconds)
    n_flagged = 0 if math.isnan(scores["coverage"]) else int(round(scores["coverage"] * scores["n_scored"]))
    row = {k: scores[k] for k in _SCORES}
    row.update(n_flagged=n_flagged, flagged_right_share=scores["accuracy_identifiable"],
               self_excited_flags=seen.self_excited_flags(), error="", fit_time_s=seconds,
               **_choice(fitted), **_change_scan(fitted, records))
    row["curve_error_energy_yaw_free"] = _yaw_free_curve_error(fitted, records, truths, scores["curve_error_energy"])
    reference_seconds = getattr(fitted, "reference_seconds", None)
    if reference_seconds is not None:  # the grey-box's own fit of its reference (NaN: reused)
        row["reference_fit_time_s"] = float(reference_seconds)
    return row, fitted


def _choice(fitted) -> dict[str, Any]:
    """The candidate a model chose from the campaign's evidence and its confidence set ("" without)."""
    ev = model_evidence(fitted)
    if ev is None:
        return {"chosen": "", "confidence_set": "", "dynamics_shown": "", "stationary": ""}
    return {"chosen": str(ev["chosen"]),
            "confidence_set": ";".join(c["name"] for c in ev["candidates"] if c["in_set"]),
            "dynamics_shown": int(bool(ev.get("dynamics_shown", True))),
            "stationary": int(bool(ev.get("stationary", True)))}


def _yaw_free_curve_error(fitted, records, truths, own: float) -> float:
    """The energy-weighted curve error of the chosen candidate's yaw-free counterpart (the same options with
    ``yaw_degree`` 0, :func:`vivbench.analysis.yaw_free_counterpart`) fitted to every event; ``own`` where the
    choice takes no yaw; NaN for a model without held-out evidence or candidates, or without such a counterpart."""
    from vivbench.analysis.candidates import yaw_free_counterpart

    ev = model_evidence(fitted)
    candidates = getattr(getattr(fitted, "model", None), "candidates", None)
    if ev is None or candidates is None:
        return math.nan
    if not next((c.options or {}) for c in candidates if c.name == ev["chosen"]).get("yaw_degree"):
        return float(own)
    twin = yaw_free_counterpart(candidates, ev["chosen"])
    return math.nan if twin is None else curve_scores(copy.deepcopy(twin.model).fit(records), records, truths)[2]


def yaw_factor_range(records, truths) -> float:
    """How much the yaw matters on a campaign: the range of the truth's factor on Y1 over its measured yaws.

    Parameters
    ----------
    records : sequence of Record, with ``yaw`` (degrees) where measured
    truths : sequence of truth datasets (the generator's configuration in ``config_json``)

    Returns
    -------
    float, 1
        max - min of the factor on a grid between the 5th and 95th percentiles of the measured yaw
        samples of every event and section; 0 without a yaw effect or without measured yaw, NaN when the
        truth's configuration cannot be read.
    """
    from vivbench.validate.greybox import truth_yaw_factor

    yaws = [np.ravel(r.yaw) for r in records if r.yaw is not None]
    yaw = np.concatenate(yaws) if yaws else np.empty(0)
    yaw = yaw[np.isfinite(yaw)]
    if not len(truths):
        return math.nan
    if not yaw.size:
        return 0.0
    lo, hi = np.percentile(yaw, [5.0, 95.0])
    factor = truth_yaw_factor(truths[0], np.linspace(lo, hi, 101))
    return math.nan if factor is None else float(np.ptp(factor))


def _change_scan(fitted, records) -> dict[str, Any]:
    """``vivbench pool``'s change scan of the model (refits before and after each split) on the measured
    records: its permutation p-value, whether it alarms and the first event after the located change
    (NaN and -1 for a model without per-event statistics)."""
    from vivbench.analysis.changes import statistics_change_scan
    from vivbench.models.model_input import measured_input

    inputs = model_change_inputs(fitted, [measured_input(fitted, r) for r in records])
    if inputs is None:
        return {"change_p_value": math.nan, "change_detected": 0, "change_index": -1}
    scan = statistics_change_scan(inputs["statistics"], seed=int(getattr(fitted, "seed", 0)))
    return {"change_p_value": float(scan["p_value"]), "change_detected": int(bool(scan["detected"])),
            "change_index": int(scan["change_index"]) if scan["detected"] else -1}


def run_study_task(task: StudyTask) -> dict[str, Any]:
    """Generate, identify and score one draw; runs in a worker.

    Returns
    -------
    dict: ``draw``, ``campaign_seed``, ``n_events``, ``events_failed``, ``labels``, ``yaw_factor_range``
    (:func:`yaw_factor_range`), ``seconds`` (wall
    time of the task), ``stage_seconds`` (``generate``, ``identify``) and ``methods`` (method name ->
    its scores with ``fit_time_s``, or NaNs and ``error`` when that method failed).
    Raises when the campaign cannot be generated or no event can be identified (the draw is retried
    by the next run).
    """
    start = time.perf_counter()
    draw = draw_bridge(task.split, task.draw)
    campaign = task.campaign(draw)
    root = task_directory(task.work_root, f"d{task.draw:05d}-")
    try:
        made = generate_campaign(campaign, root / "campaign", workers=1)
        generated = time.perf_counter()
        written, failures = identify_files(made.files, root / "identify", task.identify, workers=1)
        stages = {"generate": generated - start, "identify": time.perf_counter() - generated}
        if not written:
            reasons = list(made.failures.values()) + list(failures.values())
            raise InputError(f"no event of {task.split} draw {task.draw} could be identified "
                             f"({reasons[0] if reasons else 'nothing to identify'})")
        results = sorted(written, key=lambda p: p.name)
        identified = {p.name.removesuffix(".identify.nc") for p in results}
        events = sorted((f for f in made.files if f.stem in identified), key=lambda p: p.name)
        records, truths, windows = scoring_inputs(events, results)
        if task.wind_source == "truth":
            records = [record_with_truth_wind(r, t) for r, t in zip(records, truths)]
        if task.amplitude_source == "truth":
            records = [record_with_truth_amplitude(r, t) for r, t in zip(records, truths)]
        methods, fitted = {}, {}
        for name in _fit_order(task.methods):
            try:
                method = study_method(name, draw, fitted, tau=task.tau)
                methods[name], fitted[name] = _score(method, records, truths, windows, task.tau)
            except Exception as exc:  # one method failing must not lose the others' scores
                methods[name] = {**{k: math.nan for k in (*_SCORES, *_FLAG_COLUMNS)},
                                 "error": error_line(exc).replace(str(root), "<draw>")}
    except Exception as exc:
        raise RuntimeError(error_line(exc).replace(str(root), "<draw>")) from None
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return {"draw": task.draw, "campaign_seed": draw.campaign_seed, "n_events": campaign.n_events,
            "events_failed": len(made.failures) + len(failures), "labels": draw.labels, "methods": methods,
            "yaw_factor_range": yaw_factor_range(records, truths),
            "seconds": time.perf_counter() - start, "stage_seconds": stages}


@dataclass(frozen=True)
class StudyResult:
    """What :func:`run_study` did.

    Attributes
    ----------
    table, summary, page : ``study.csv``, ``summary.json``, ``study.md``
    computed : draws computed by this call; resumed : draws found finished in the journal
    failures : draw -> one-line error (retried by the next call)
    seconds : draw -> wall time of its task (computed by this call or an earlier one), s
    repaired_lines : corrupt or half-written journal lines dropped on start
    """

    table: Path
    summary: Path
    page: Path
    computed: tuple[int, ...]
    resumed: tuple[int, ...]
    failures: dict[int, str]
    seconds: dict[int, float]
    repaired_lines: int


def _csv_rows(config: StudyConfig, done: dict[int, dict]) -> list[dict[str, Any]]:
    rows = []
    for d in config.draws:
        if d not in done:
            continue
        rec = done[d]
        labels = rec["labels"]
        for name in config.methods:
            scores = rec["methods"].get(name)
            if scores is None:  # a method added to a finished draw is not scored
                continue
            row = {"split": config.split, "draw": d, "method": name, "campaign_seed": rec["campaign_seed"],
                   "n_events": rec["n_events"], "events_failed": rec["events_failed"]}
            row.update({c: _label_text(labels.get(c)) for c in LABEL_COLUMNS})
            row["yaw_factor_range"] = rec.get("yaw_factor_range", math.nan)
            row.update({k: scores.get(k, math.nan) for k in (*_SCORES, *_FLAG_COLUMNS)})
            row["error"] = scores.get("error", "")
            rows.append(row)
    return rows


def _label_text(value) -> Any:
    if isinstance(value, (list, tuple)):
        return "-".join(format_value(float(v)) for v in value)
    return "" if value is None else value


def _write_csv(path: Path, rows: Sequence[dict]) -> None:
    import csv
    import io

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(STUDY_COLUMNS)
    for row in rows:
        writer.writerow([format_value(row.get(c, "")) for c in STUDY_COLUMNS])
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")


def _check_config_record(out: Path, config: StudyConfig) -> None:
    data = config.to_dict()
    del data["draws"]
    check_record(out / "study_config.json", config.fingerprint(), data,
                 "this directory holds a study of another split, methods, caps, identification or wind source; use "
                 "another --out (or delete the directory to start over)")


def run_study(config: StudyConfig, out_dir: str | Path, *, workers: int = 1, scheduler: str | None = None,
              progress: Callable[[int, int], None] | None = None) -> StudyResult:
    """Run (or resume) a study and write ``study.csv``, ``summary.json`` and ``study.md``.

    Parameters
    ----------
    config : StudyConfig
    out_dir : output directory; it also holds ``study_config.json`` (a study of another split,
        methods, caps or identification is refused) and the journal ``study.jsonl``
    workers : local worker processes (1: this process), when ``scheduler`` is None
    scheduler : None, ``"local:N"`` (a dask LocalCluster) or a dask scheduler address
    progress : optional ``progress(n_done, n_total)``, on start and after every draw

    Returns
    -------
    StudyResult
        The files do not depend on ``workers``, ``scheduler`` or on interruptions.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kind, _ = parse_scheduler(scheduler)
    with exclusive_directory(out, ".study.lock", "study"):
        _check_config_record(out, config)
        journal = out / "study.jsonl"
        done, repaired = journal_load(journal, n_tasks=_MAX_DRAW, columns=_JOURNAL_COLUMNS)
        resumed = tuple(d for d in config.draws if d in done)
        work = out / ".work"
        shutil.rmtree(work, ignore_errors=True)
        work_root = str(work) if kind != "address" else None
        pending = [dataclasses.replace(t, work_root=work_root) for t in study_tasks(config) if t.draw not in done]
        if progress is not None:
            progress(len(resumed), len(config.draws))
        try:
            computed, failures = run_journalled(
                run_study_task, pending, journal, done, task_id=lambda t: t.draw,
                failed_row=lambda t: {"draw": t.draw, "methods": {}}, workers=workers, scheduler=scheduler,
                progress=None if progress is None else counting_progress(progress, len(resumed), len(config.draws)))
        finally:
            shutil.rmtree(work, ignore_errors=True)
        rows = _csv_rows(config, done)
        table, summary_path, page = out / "study.csv", out / "summary.json", out / "study.md"
        _write_csv(table, rows)
        summary = study_summary(config.to_dict(), rows, failed=sorted(failures))
        with atomic_path(summary_path) as tmp:
            tmp.write_text(json.dumps(summary, indent=1, sort_keys=True, allow_nan=True) + "\n", encoding="utf-8")
        with atomic_path(page) as tmp:
            tmp.write_text(study_markdown(summary), encoding="utf-8")
    seconds = {d: float(done[d]["seconds"]) for d in config.draws if d in done and "seconds" in done[d]}
    return StudyResult(table=table, summary=summary_path, page=page, computed=tuple(sorted(computed)),
                       resumed=resumed, failures=failures, seconds=seconds, repaired_lines=repaired)
