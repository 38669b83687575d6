"""Study: the errors in the measured wind, how much of the campaign model's error they make, and whether SIMEX undoes it.

Run::

    python benchmarks/run_study.py wind_errors --split development --draws 0-29 --out DIR \
        [--max-events N] [--max-duration 30] [--workers 2]

Fitted on the wind the truth's dynamics sees instead of the anemometers', the varying campaign
model's energy-weighted dA/dt error falls most on the draws whose deck feels a smooth wind while
each anemometer sees its own point turbulence (docs/results/studies/truth_wind). This study asks
two questions on the same records.

1. Is it the size and spectrum of the wind's error, or something else in the measured wind? The
   model is fitted on the truth's wind plus a surrogate of each section's actual error, the
   measured wind minus the truth's (``truth_plus_noise``): the same amplitude spectrum with
   random phases, so the same size and time scales but no alignment with the events' dynamics.
   If that brings the error back to the one on the measured wind, the loss is the error's size
   and time scales.
2. Does a standard errors-in-variables correction recover it? SIMEX (simulation-extrapolation,
   Cook & Stefanski 1994): the model is refitted with more noise added to the measured wind, at
   variances lambda times the wind error's (lambda in :data:`LAMBDAS`, :data:`REPLICATES` draws
   each), and its dA/dt at the truth's (A, U) is extrapolated to lambda = -1 (no error) by a
   quadratic (``simex``) or a straight line (``simex_linear``) in lambda fitted by least squares
   through lambda = 0 (the fit on the measured wind) and the perturbed fits. The added error is
   either what a user can estimate (smooth Gaussian noise, :func:`vivbench.analysis.perturbed_wind`
   with time scale :data:`NOISE_TIMESCALE_S`, of the rms :func:`vivbench.analysis.wind_error_scale`
   estimates: the spread between the sections' anemometers, or a stated share of the mean wind for
   one section) or, as an oracle no user has, surrogates of the actual error of question 1
   (``simex_oracle``).

Every variant fits the candidate that the default selection (``vivbench pool``) chooses on the
measured records, with its options fixed and no bootstrap (``measured`` is that refit; the
selection's own error is in the rows as ``error_selection``). Scores: the energy-weighted
relative dA/dt error on the truth's own (A, U) over every sample, as everywhere in vivbench. The
summary gives per variant the median, 90th percentile and worst over the draws, the median ratio
to ``measured`` with the draws better and worse by more than 10 %, and the same by the draws' kind
of wind error; the rows give the actual and the estimated rms of the model's wind input error.

Development draws only: the study decides whether a correction is worth building. The study
directory ``--out`` keeps each draw's campaign, identification and scores; rerunning with the same
options continues it, and a directory copied from another study of the same caps is read.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402

import numpy as np  # noqa: E402

#: The variants, ``measured`` first (the others are paired with it).
VARIANTS = ("measured", "truth", "truth_plus_noise", "simex", "simex_linear", "simex_oracle")

#: SIMEX's added error variances, in units of the wind error's variance.
LAMBDAS = (0.5, 1.0, 1.5, 2.0)

#: Noise draws per added variance.
REPLICATES = 2

#: s: the time scale of the simulated anemometer errors (that of the verdict's wind perturbations,
#: ``varying_selection(perturbation_timescale_s=60)``).
NOISE_TIMESCALE_S = 60.0


def extrapolation_weights(lambdas, degree: int) -> np.ndarray:
    """Weights w (one per lambda) with sum_l w_l f(lambda_l) the least-squares polynomial of ``degree`` in lambda
    through the points (lambda_l, f_l), evaluated at lambda = -1; shape (len(lambdas),)."""
    lam = np.asarray(lambdas, dtype=float)
    V = np.vander(lam, degree + 1)
    at = (-1.0) ** np.arange(degree, -1, -1)
    return at @ np.linalg.pinv(V)


def _rhs_at_truth(model, records, truths) -> tuple[np.ndarray, np.ndarray]:
    """The model's dA/dt and the truth's on the truth's (A, U) of every event, concatenated (n, S), m/s."""
    from vivbench.validate import model_rhs_true_AU, record_yaw_on

    fm, ft = [], []
    for rec, truth in zip(records, truths):
        _, a, b = model_rhs_true_AU(model, truth, event_id=rec.event_id,
                                    yaw=record_yaw_on(rec, truth["time"].values))
        fm.append(a)
        ft.append(b)
    return np.concatenate(fm), np.concatenate(ft)


def _actual_scales(records, truth_records, smoothing_s: float) -> list[np.ndarray]:
    """Per record, each section's rms error of its measured wind smoothed as the model smooths it, about the
    truth's wind; shapes (S,), m/s."""
    from vivbench.preprocess.wind_smoothing import smooth_wind

    out = []
    for rec, tr in zip(records, truth_records):
        d = smooth_wind(rec, smoothing_s).U - tr.U
        out.append(np.sqrt(np.nanmean(d**2, axis=0)))
    return out


def surrogate(x: np.ndarray, rng) -> np.ndarray:
    """A phase-randomised surrogate of each column of ``x`` (n, S): the same amplitude spectrum (so the same
    variance and autocorrelation, circularly) with independent uniform random phases; the mean kept."""
    X = np.fft.rfft(x, axis=0)
    phase = np.exp(2j * np.pi * rng.random(X.shape))
    phase[0] = 1.0
    if x.shape[0] % 2 == 0:
        phase[-1] = np.where(phase[-1].real < 0, -1.0, 1.0)  # the Nyquist term stays real
    return np.fft.irfft(X * phase, n=x.shape[0], axis=0)


def _with_surrogates(records, errors, factor: float, rng) -> list:
    """``records`` with ``factor`` times a surrogate of each record's wind error (n, S) added to its U."""
    import dataclasses

    return [dataclasses.replace(rec, U=rec.U + factor * surrogate(err, rng)) for rec, err in zip(records, errors)]


def _perturbed(records, scales, factor: float, rng) -> list:
    from vivbench.analysis import perturbed_wind

    return [perturbed_wind(rec, factor * s, NOISE_TIMESCALE_S, rng) for rec, s in zip(records, scales)]


def score_draw(task: dict) -> dict:
    """One draw: the default selection's choice, then every variant's fit of it, scored on the truth."""
    from vivbench.analysis import VARYING_PRIORS, wind_error_scale
    from vivbench.models import VaryingCoefficientSINDy
    from vivbench.models.protocol import model_evidence
    from vivbench.validate import energy_relative_error, record_with_truth_wind
    from vivbench.validate.methods import CampaignMethod

    from benchmarks._family_args import draw_inputs, labelled_row, store_row, stored_row

    done = stored_row(task)
    if done is not None:
        return done
    labels, row = labelled_row(task)
    row["point_intensity"] = float(labels["point_intensity"] or math.nan)
    records, truths, _windows = draw_inputs(task)
    row["n_events"] = len(records)
    selection = CampaignMethod("varying").fit(records)
    evidence = model_evidence(selection)
    row["chosen"] = str(evidence["chosen"])
    options = next(c["options"] for c in evidence["candidates"] if c["name"] == evidence["chosen"])

    def fit(recs):
        return VaryingCoefficientSINDy(**{**VARYING_PRIORS, **options}, n_bootstrap=0).fit(recs)

    smoothing = float(VARYING_PRIORS["wind_smoothing_s"])
    truth_records = [record_with_truth_wind(r, t) for r, t in zip(records, truths)]
    actual = _actual_scales(records, truth_records, smoothing)
    estimated = [wind_error_scale(r, smoothing) for r in records]
    weights = [r.n_samples for r in records]  # rms over samples, pooled over events and sections
    row["wind_error_actual"] = float(np.sqrt(np.average([np.mean(a**2) for a in actual], weights=weights)))
    row["wind_error_estimated"] = float(np.sqrt(np.average([np.mean(e**2) for e in estimated], weights=weights)))
    raw_errors = [np.nan_to_num(r.U - tr.U) for r, tr in zip(records, truth_records)]  # (n, S) each, m/s
    rng = np.random.default_rng(task["draw"])
    f0, f_true = _rhs_at_truth(fit(records), records, truths)
    preds = {"measured": f0, "truth": _rhs_at_truth(fit(truth_records), records, truths)[0],
             "truth_plus_noise": _rhs_at_truth(fit(_with_surrogates(truth_records, raw_errors, 1.0, rng)), records,
                                               truths)[0]}
    lam = (0.0,) + LAMBDAS
    added = {"simex": lambda f: _perturbed(records, estimated, f, rng),
             "simex_oracle": lambda f: _with_surrogates(records, raw_errors, f, rng)}
    for name, perturb in added.items():
        curve = [f0]
        for level in LAMBDAS:
            reps = [_rhs_at_truth(fit(perturb(math.sqrt(level))), records, truths)[0] for _ in range(REPLICATES)]
            curve.append(np.mean(reps, axis=0))
        curve = np.stack(curve)
        preds[name] = np.tensordot(extrapolation_weights(lam, 2), curve, axes=1)
        if name == "simex":
            preds["simex_linear"] = np.tensordot(extrapolation_weights(lam, 1), curve, axes=1)
    row["error_selection"] = energy_relative_error(_rhs_at_truth(selection, records, truths)[0], f_true)
    for name in VARIANTS:
        row[f"error_{name}"] = energy_relative_error(preds[name], f_true)
    return store_row(task, row)


def summarise(rows: list[dict]) -> list[dict]:
    """One row per variant and kind of wind error (all draws first): errors and the pairing with ``measured``."""
    from _family_args import by_wind_error, paired, spread

    out = []
    for kind, sub in by_wind_error(rows):
        for name in VARIANTS:
            err = spread(r[f"error_{name}"] for r in sub)
            pair = paired(sub, f"error_{name}", "error_measured")
            out.append({"variant": name, "draws_of": kind, "draws": len(sub), "error_median": err["median"],
                        "error_p90": err["p90"], "error_worst": err["worst"],
                        "ratio_to_measured_median": pair["ratio_median"], "better_by_10pct": pair["better_by_10pct"],
                        "worse_by_10pct": pair["worse_by_10pct"]})
    return out


def findings(summary: list[dict], rows: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    said = []
    for s in summary:
        text = (f"{s['variant']}, {s['draws_of']} draws ({s['draws']}): energy-weighted dA/dt error median "
                f"{s['error_median']:.3f}, p90 {s['error_p90']:.3f}, worst {s['error_worst']:.3f}")
        if s["variant"] != "measured":
            text += (f"; paired with the fit on the measured wind: median ratio {s['ratio_to_measured_median']:.2f}, "
                     f"better by more than 10 % on {s['better_by_10pct']} draws and worse on {s['worse_by_10pct']}")
        said.append(text + ".")
    ratio = [r["wind_error_estimated"] / r["wind_error_actual"] for r in rows
             if r["wind_error_actual"] > 0 and np.isfinite(r["wind_error_estimated"])]
    for label, sub in (("two sections or more", [r for r in rows if r["n_sections"] > 1]),
                       ("one section", [r for r in rows if r["n_sections"] == 1])):
        q = [r["wind_error_estimated"] / r["wind_error_actual"] for r in sub if r["wind_error_actual"] > 0]
        if q:
            said.append(f"The estimated wind error over the actual one, {label} ({len(q)} draws): median "
                        f"{np.median(q):.2f}, from {min(q):.2f} to {max(q):.2f}.")
    if not ratio:
        said.append("No draw had an actual wind error to compare the estimate with.")
    return said


def main(argv=None) -> dict:
    from _family_args import family_parser, run_draws

    args = family_parser(__doc__.splitlines()[0], max_duration=30.0).parse_args(argv)
    draws, rows, failed = run_draws("study_wind_errors", "score_draw", args)
    summary = summarise(rows) if rows else []
    return {"findings": findings(summary, rows), "split": args.split, "draws": draws, "lambdas": list(LAMBDAS),
            "replicates": REPLICATES, "noise_timescale_s": NOISE_TIMESCALE_S, "max_events": args.max_events,
            "max_duration_min": args.max_duration, "failed_draws": failed, "summary": summary, "rows": rows}


if __name__ == "__main__":
    main()
