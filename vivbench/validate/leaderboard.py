"""The leaderboard: every method scored on every scenario of the suite (docs/methods.md).

``run_leaderboard(methods, scenarios, out_dir)`` runs in two stages, each
through :func:`vivbench.core.parallel.run_tasks` (this process, local worker
processes or dask.distributed):

1. **Scenarios.** Each scenario's campaign is generated once and identified by
   the chain (:func:`vivbench.analysis.identify_files`, the same windows for
   every method) under ``OUT/scenarios/<name>/`` (``campaign/``,
   ``identify/``), and ``scenario.json`` records the scenario (name, version,
   fingerprint) and the identification settings. A later run reuses the
   directory when that record is the same and regenerates it otherwise (a new
   scenario version, other identification settings); cells scored on an old
   campaign are then not reused. The description does not enter.
2. **Cells.** Every (scenario, method) cell fits the method on the scenario's
   records and scores it (:mod:`vivbench.validate.methods`: the same scores for
   built-in and plug-in methods). Each finished cell is written at once,
   atomically, to ``OUT/cells/<scenario>/<method>.json``; a stopped run resumes
   where it stopped (finished cells are read back, not recomputed). A cell that
   fails is reported and retried by the next run; the others finish.

The tables are rebuilt from the cell files in suite order (scenarios, then
methods as given), so they do not depend on the worker count, the backend or
the completion order; only ``fit_time_s`` (wall time) varies between runs.
With a remote scheduler ``OUT`` must be on a file system the workers share.

Outputs: ``leaderboard.csv`` (one row per cell), ``leaderboard.md`` (one
table per score, scenarios by methods, with the scenario legend and what is
not applicable) and ``leaderboard.png`` (one heat map per score).
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from collections.abc import Callable, Sequence
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

from vivbench.core.errors import InputError, error_line
from vivbench.core.lock import exclusive_directory
from vivbench.core.parallel import run_tasks
from vivbench.io.netcdf import atomic_path
from vivbench.validate.leaderboard_table import VALUES, plot_leaderboard, write_csv, write_markdown
from vivbench.validate.scenarios import Scenario

__all__ = ["LeaderboardResult", "run_leaderboard", "method_slug", "parse_methods"]


#: Where each leaderboard column comes from in :func:`vivbench.validate.methods.score_fitted`'s dict.
SCORE_SOURCES = {
    "coverage": "coverage",
    "accuracy_flagged": "accuracy_identifiable",
    "accuracy_all": "accuracy_all",
    "rhs_error_true_AU": "rhs_error_true_AU_median_active",
    "rhs_error_true_AU_energy": "rhs_error_true_AU_energy",
    "curve_error": "curve_error_total",
    "curve_error_energy": "curve_error_energy",
    "forecast_nmse": "simulation_nmse",
    "forecast_covered": "simulation_covered",
    "fit_time_s": "fit_time_s",
}

_CELL_FORMAT = "vivbench-leaderboard-cell"
_CELL_FORMAT_VERSION = 1


def parse_methods(methods: str | Sequence[str]) -> list[str]:
    """Method specs from comma-separated text or a list; distinct, at least one."""
    if isinstance(methods, str):
        methods = [m.strip() for m in methods.split(",") if m.strip()]
    methods = list(methods)
    if not methods:
        raise InputError("no method named: give e.g. "
                         "--methods windows,pooled,varying,pysindy-cp,binned,pkg.mod:factory")
    if len(set(methods)) != len(methods):
        raise InputError(f"methods named twice: {', '.join(methods)}")
    return methods


def method_slug(spec: str) -> str:
    """A file name for a method spec: its safe characters plus a short hash (specs differing only in
    unsafe characters do not collide)."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "-", spec).strip("-.") or "method"
    return f"{safe[:60]}-{hashlib.sha256(spec.encode()).hexdigest()[:8]}"


# ------------------------------------------------------------------ scenarios


def _identify_config(identify):
    from vivbench.analysis.identify import IdentifyConfig

    return identify if identify is not None else IdentifyConfig()


def _scenario_record(scn: Scenario, identify) -> str:
    """The text of ``scenario.json``: what the campaign and its identification depend on."""
    return json.dumps({"scenario": scn.to_dict(), "fingerprint": scn.fingerprint(),
                       "identify": json.loads(identify.to_json())}, indent=1, sort_keys=True) + "\n"


def _record_key(record_text: str) -> str | None:
    """SHA-256 of a scenario record without its description (words do not change a campaign); None if broken."""
    try:
        data = json.loads(record_text)
        data["scenario"].pop("description", None)
    except (ValueError, TypeError, KeyError, AttributeError):
        return None
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def _scenario_files(directory: Path) -> tuple[list[str], list[str]]:
    """(event files, result files) of a prepared scenario directory, paired by event id."""
    from vivbench.io.event import list_events

    events = list_events(directory / "campaign")
    pairs = [(e, directory / "identify" / f"{e.stem}.identify.nc") for e in events]
    return [str(e) for e, r in pairs if r.is_file()], [str(r) for e, r in pairs if r.is_file()]


def _prepare_scenario(task: dict) -> dict:
    """Generate and identify one scenario's campaign (a worker task); write ``scenario.json`` last."""
    from vivbench.analysis.identify import identify_files
    from vivbench.synth.campaign import generate_campaign

    out = Path(task["dir"])
    scn: Scenario = task["scenario"]
    for sub in ("campaign", "identify"):
        shutil.rmtree(out / sub, ignore_errors=True)
    (out / "scenario.json").unlink(missing_ok=True)
    made = generate_campaign(scn.campaign_config(), out / "campaign", workers=1)
    if made.failures:
        event, message = sorted(made.failures.items())[0]
        raise RuntimeError(f"scenario {scn.name}: event {event} failed to generate: {message}")
    written, failures = identify_files(made.files, out / "identify", task["identify"], workers=1)
    if failures:
        path, message = sorted(failures.items())[0]
        raise RuntimeError(f"scenario {scn.name}: {Path(path).name} failed to identify: {message}")
    with atomic_path(out / "scenario.json") as tmp:
        tmp.write_text(task["record"])
    events, results = _scenario_files(out)
    return {"events": events, "results": results}


def _prepare_scenario_reported(task: dict) -> dict:
    try:
        return _prepare_scenario(task)
    except (InputError, OSError):
        raise
    except Exception as exc:
        raise RuntimeError(error_line(exc)) from exc


# ---------------------------------------------------------------------- cells


def _score_cell(task: dict) -> dict:
    """Fit and score one method on one scenario (a worker task): the cell's scores.

    Every method gets the same records (the identification results' A, U and the chain's dA,
    :func:`vivbench.analysis.records_from_results`) and is scored on the same windows (the
    identification's) against the events' ``/truth``, by :mod:`vivbench.validate.methods`.
    """
    from vivbench.validate.methods import fit_method, resolve_method, score_fitted, scoring_inputs

    records, truths, windows = scoring_inputs(task["events"], task["results"])
    if task["method"] == "greybox":  # given the scenario bridge's structural properties, never its aerodynamics
        from vivbench.validate.greybox_method import GreyBoxMethod, structural_properties

        method = GreyBoxMethod(structural_properties(task["scenario"].generator_config().structure))
    else:
        method = resolve_method(task["method"])
    fitted, seconds = fit_method(method, records)
    scores = score_fitted(fitted, records, truths, windows=windows, fit_time_s=seconds)
    # Adapter (the scoring API has no such key): whether the fitted model gives a verdict, which
    # tells "coverage 0: no verdict" from "coverage 0: flagged nothing".
    has_verdict = callable(getattr(fitted, "identifiable", None))
    return {"has_verdict": has_verdict, **{ours: scores[theirs] for ours, theirs in SCORE_SOURCES.items()}}


def _cell_path(out: Path, scenario: str, method: str) -> Path:
    return out / "cells" / scenario / f"{method_slug(method)}.json"


def _cell_text(scn: Scenario, record_key: str, method: str, scores: dict) -> str:
    row = {k: _number(scores.get(k)) for k in VALUES}
    body = {"format": _CELL_FORMAT, "format_version": _CELL_FORMAT_VERSION, "scenario": scn.name,
            "scenario_version": scn.version, "scenario_record": record_key, "method": method,
            "has_verdict": bool(scores.get("has_verdict", False)), "scores": row}
    return json.dumps(body, indent=1, sort_keys=True, allow_nan=True) + "\n"


def _number(value) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        return float("nan")
    return out


def _read_cell(path: Path, scn: Scenario, record_key: str, method: str) -> dict | None:
    """A finished cell's row, or None when the file is absent, broken or from another campaign or method."""
    try:
        body = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(body, dict) or body.get("format") != _CELL_FORMAT \
            or body.get("format_version") != _CELL_FORMAT_VERSION:
        return None
    if body.get("scenario") != scn.name or body.get("scenario_record") != record_key or body.get("method") != method:
        return None
    scores = body.get("scores")
    if not isinstance(scores, dict) or set(VALUES) - set(scores):
        return None
    return {"has_verdict": bool(body.get("has_verdict")), **{k: _number(scores[k]) for k in VALUES}}


# ------------------------------------------------------------------------ run


@dataclass(frozen=True)
class LeaderboardResult:
    """What a call of :func:`run_leaderboard` did.

    Attributes
    ----------
    rows : one dict per cell (``LEADERBOARD_COLUMNS``), scenarios then methods in the order given
    table, markdown, figure : the files written
    computed : (scenario, method) cells computed by this call
    resumed : cells read back from an earlier run
    prepared : scenarios generated and identified by this call (the others were reused)
    failures : "scenario NAME" or "cell NAME / METHOD" -> one-line message
    """

    rows: list[dict]
    table: Path
    markdown: Path
    figure: Path
    computed: tuple[tuple[str, str], ...]
    resumed: tuple[tuple[str, str], ...]
    prepared: tuple[str, ...]
    failures: dict[str, str]


def _exclusive(out: Path):
    # Two runs writing one directory would regenerate each other's campaigns.
    return exclusive_directory(out, ".leaderboard.lock", "leaderboard run")


def run_leaderboard(methods: Sequence[str], scenarios: Sequence[Scenario], out_dir: str | Path, *,
                    workers: int = 1, scheduler: str | None = None, identify=None, rerun: Sequence[str] = (),
                    progress: Callable[[str, str, str | None], None] | None = None) -> LeaderboardResult:
    """Score every method on every scenario and write the leaderboard (see the module docstring).

    Parameters
    ----------
    methods : method specs, as :func:`vivbench.validate.methods.resolve_method` takes them:
        ``"windows"``, ``"pooled"``, ``"varying"``, ``"pysindy-cp"``, ``"binned"`` or ``"package.module:factory"``;
        or ``"greybox"``: :class:`vivbench.validate.greybox_method.GreyBoxMethod` given each scenario bridge's
        structural properties (:func:`vivbench.validate.greybox_method.structural_properties`)
    scenarios : the scenarios (e.g. :func:`vivbench.validate.select_scenarios`)
    out_dir : output directory (created); rerunning into it resumes
    workers, scheduler : see :func:`vivbench.core.parallel.run_tasks`
    identify : IdentifyConfig of the chain that makes every scenario's records and windows (default settings)
    rerun : methods (among ``methods``) whose finished cells are computed again. A cell is keyed by the
        scenario's record and the method's spec, not by the method's code: after changing a method,
        rerun it (or delete its files under ``OUT/cells/``)
    progress : optional ``progress(kind, scenario, method)``, called with ``"scenario"`` (method None)
        after each scenario is ready and ``"cell"`` after each cell, resumed ones included

    Returns
    -------
    LeaderboardResult
    """
    methods = parse_methods(methods)
    scenarios = list(scenarios)
    if not scenarios:
        raise InputError("no scenario to run")
    names = [s.name for s in scenarios]
    if len(set(names)) != len(names):
        raise InputError(f"scenarios named twice: {', '.join(names)}")
    rerun = parse_methods(rerun) if rerun else []
    unknown = [m for m in rerun if m not in methods]
    if unknown:
        raise InputError(f"rerun names methods that are not run: {', '.join(unknown)}; methods: {', '.join(methods)}")
    identify = _identify_config(identify)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with _exclusive(out):
        return _run(methods, scenarios, out, workers, scheduler, identify, set(rerun), progress)


def _run(methods, scenarios, out, workers, scheduler, identify, rerun, progress) -> LeaderboardResult:
    records = {s.name: _scenario_record(s, identify) for s in scenarios}
    keys = {name: _record_key(text) for name, text in records.items()}
    files: dict[str, dict] = {}
    failures: dict[str, str] = {}
    todo = []
    for s in scenarios:
        d = out / "scenarios" / s.name
        marker = d / "scenario.json"
        if marker.is_file() and _record_key(marker.read_text()) == keys[s.name]:
            events, results = _scenario_files(d)
            if events and len(events) == s.n_events:
                if marker.read_text() != records[s.name]:  # a new description: the legend reads it from here
                    with atomic_path(marker) as tmp:
                        tmp.write_text(records[s.name])
                files[s.name] = {"events": events, "results": results}
                if progress is not None:
                    progress("scenario", s.name, None)
                continue
        todo.append(s)
    tasks = [{"dir": str(out / "scenarios" / s.name), "scenario": s, "identify": identify,
              "record": records[s.name]} for s in todo]
    prepared = []
    with closing(run_tasks(_prepare_scenario_reported, tasks, workers=workers, scheduler=scheduler)) as outcomes:
        for o in outcomes:
            s = todo[o.index]
            if o.ok:
                files[s.name] = o.value
                prepared.append(s.name)
            else:
                failures[f"scenario {s.name}"] = o.error
            if progress is not None:
                progress("scenario", s.name, None)

    rows_by_cell: dict[tuple[str, str], dict] = {}
    errors: dict[tuple[str, str], str] = {}
    resumed, pending = [], []
    by_name = {s.name: s for s in scenarios}
    for s in scenarios:
        for m in methods:
            if s.name not in files:
                errors[(s.name, m)] = "scenario failed"
                continue
            row = None if m in rerun else _read_cell(_cell_path(out, s.name, m), s, keys[s.name], m)
            if row is not None:
                rows_by_cell[(s.name, m)] = row
                resumed.append((s.name, m))
                if progress is not None:
                    progress("cell", s.name, m)
            else:
                pending.append((s.name, m))
    cell_tasks = [{"method": m, "events": files[sn]["events"], "results": files[sn]["results"], "scenario": by_name[sn]}
                  for sn, m in pending]
    computed = []
    with closing(run_tasks(_score_cell, cell_tasks, workers=workers, scheduler=scheduler)) as outcomes:
        for o in outcomes:
            sn, m = pending[o.index]
            if o.ok:
                text = _cell_text(by_name[sn], keys[sn], m, o.value)
                path = _cell_path(out, sn, m)
                with atomic_path(path) as tmp:
                    tmp.write_text(text)
                rows_by_cell[(sn, m)] = _read_cell(path, by_name[sn], keys[sn], m)
                computed.append((sn, m))
            else:
                errors[(sn, m)] = o.error
                failures[f"cell {sn} / {m}"] = o.error
                # a rerun that failed must not leave the old result to be resumed next time
                _cell_path(out, sn, m).unlink(missing_ok=True)
            if progress is not None:
                progress("cell", sn, m)

    rows = []
    for s in scenarios:
        for m in methods:
            row = {"scenario": s.name, "scenario_version": s.version, "in_class": s.in_class, "method": m,
                   "has_verdict": False, **{k: float("nan") for k in VALUES}, "error": ""}
            row.update(rows_by_cell.get((s.name, m), {}))
            row["error"] = errors.get((s.name, m), "")
            rows.append(row)
    table = write_csv(rows, out / "leaderboard.csv")
    figure = plot_leaderboard(rows, out / "leaderboard.png")
    markdown = write_markdown(rows, scenarios, out / "leaderboard.md", figure=figure.name)
    order = {s.name: i for i, s in enumerate(scenarios)}
    return LeaderboardResult(rows=rows, table=table, markdown=markdown, figure=figure, computed=tuple(computed),
                             resumed=tuple(resumed), prepared=tuple(sorted(prepared, key=order.get)),
                             failures=dict(sorted(failures.items())))
