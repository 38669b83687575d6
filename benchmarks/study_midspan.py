"""Study: one anemometer at mid-span for three or four acceleration sections, with and without the widening.

Run::

    python benchmarks/run_study.py midspan --split development --draws 0-29 --out DIR \
        [--max-events 8] [--max-duration 30] [--anemometers 0.5] [--wind-rule nearest]

Draws of the generator family's ``--split`` among ``--draws`` whose bridge has 3 or 4
sections are generated with the anemometers of ``--anemometers`` (fractions of the span;
default one at mid-span) instead of one per section (``vivbench study --anemometers``):
each section's recorded wind is the nearest anemometer's, the deck feels its own
section's wind, and the events record each section's distance to its anemometer
(``wind_distance_m_<section>``). Each campaign is identified and two methods are scored
against the truth by :func:`vivbench.validate.run_study`:

- ``varying``: the varying campaign model as ``vivbench pool`` fits it, whose verdict's
  errors-in-variables treatment adds each section's wind error over its distance
  (:func:`vivbench.preprocess.unmeasured_wind_error`): in the wind perturbations of the
  refits a flag must survive, and as a shift of those sections' winds by -+1.96 errors
  under which the chosen model must give the same regime;
- ``unwidened``: the same with the distances removed from every record it is fitted on or
  asked about (:func:`varying_without_widening`), i.e. what the chain did before the
  distance was read: one anemometer copied to every section shows no spread, so no wind
  error at all.

Per draw and method the rows give the number of flagged window-equations, the share of
them whose regime is right (the verdict's promise: >= 0.95), the coverage and the
energy-weighted relative dA/dt error on the truth's own (A, U). ``--max-events`` and
``--max-duration`` (minutes) cap the campaigns (smaller than the family's; the rows say so).
The study directory ``--out`` is resumable: rerunning with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import csv  # noqa: E402
import dataclasses  # noqa: E402

from vivbench.core.record import Record  # noqa: E402
from vivbench.synth.family import draw_bridge  # noqa: E402
from vivbench.validate.methods import resolve_method  # noqa: E402
from vivbench.validate.study import StudyConfig, parse_draws, run_study  # noqa: E402

#: The study's method spec of :func:`varying_without_widening` (importable with the repository on the path).
UNWIDENED = "benchmarks.study_midspan:varying_without_widening"
#: Section counts the study keeps.
SECTIONS = (3, 4)


def _blind(value):
    """A record without its ``wind_distance`` (anything else as it is)."""
    if isinstance(value, Record) and value.wind_distance is not None:
        return dataclasses.replace(value, wind_distance=None)
    return value


class _BlindModel:
    """A fitted method that never sees a record's ``wind_distance``: every call gets the records without it."""

    def __init__(self, fitted):
        self._fitted = fitted

    def __getattr__(self, name):
        attr = getattr(self.__dict__["_fitted"], name)
        if not callable(attr):
            return attr
        return lambda *args, **kwargs: attr(*map(_blind, args), **{k: _blind(v) for k, v in kwargs.items()})


class _WithoutDistance:
    """The ``varying`` method fitted and evaluated on records whose ``wind_distance`` is removed."""

    def __init__(self):
        self.method = resolve_method("varying")

    def fit(self, records):
        return _BlindModel(self.method.fit([_blind(r) for r in records]))


def varying_without_widening():
    """The ``varying`` study method blind to the recorded distances (the chain before it read them)."""
    return _WithoutDistance()


def kept_draws(split: str, draws) -> tuple[int, ...]:
    """The draws among ``draws`` whose bridge has 3 or 4 sections (nothing simulated)."""
    return tuple(d for d in draws if draw_bridge(split, d).labels["n_sections"] in SECTIONS)


def main(argv=None) -> dict:
    from _family_args import family_parser

    parser = family_parser(__doc__.splitlines()[0],
                           draws_help="N, N-M or a comma-separated list; those with 3-4 sections run")
    parser.add_argument("--limit", type=int, default=None, help="at most this many of them, in draw order")
    parser.add_argument("--anemometers", default="0.5", help="fractions of the span length (default 0.5)")
    parser.add_argument("--wind-rule", default="nearest", choices=("nearest", "interpolation"))
    args = parser.parse_args(argv)
    draws = kept_draws(args.split, parse_draws(args.draws))[:args.limit]
    if not draws:
        parser.error(f"no draw of {args.draws} has {' or '.join(map(str, SECTIONS))} sections")
    config = StudyConfig(split=args.split, draws=draws, methods=("varying", UNWIDENED), max_events=args.max_events,
                         max_duration=None if args.max_duration is None else args.max_duration * 60.0,
                         anemometer_span=tuple(float(x) for x in args.anemometers.split(",")),
                         wind_rule=args.wind_rule)
    result = run_study(config, args.out, workers=args.workers)
    with open(result.table, encoding="utf-8") as fh:
        table = list(csv.DictReader(fh))
    names = {"varying": "varying", UNWIDENED: "unwidened"}
    rows = []
    for row in table:
        n_flagged = int(float(row["n_flagged"])) if row["n_flagged"] not in ("", "nan") else 0
        rows.append({"draw": int(row["draw"]), "method": names[row["method"]], "n_sections": int(row["n_sections"]),
                     "eiv": row["eiv"], "forced_only": row["forced_only"], "n_events": int(row["n_events"]),
                     "n_flagged": n_flagged, "flagged_right_share": _num(row["flagged_right_share"]),
                     "coverage": _num(row["coverage"]), "dA_error_energy": _num(row["rhs_error_true_AU_energy"]),
                     "promise_kept": ("" if n_flagged < 20 else
                                      str(_num(row["flagged_right_share"]) >= 0.95).lower()),
                     "error": row["error"]})
    return {"split": args.split, "draws": list(draws), "anemometers": args.anemometers, "wind_rule": args.wind_rule,
            "max_events": args.max_events, "max_duration_min": args.max_duration,
            "failed_draws": sorted(result.failures), "rows": rows}


def _num(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")


if __name__ == "__main__":
    main()
