"""``vivbench pool``: one model for a whole campaign and the regimes it gives every window."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from vivbench.core.errors import InputError

#: The built-in campaign models of ``--model``: VaryingCoefficientSINDy and PooledSINDy (or a user's model
#: of the protocol, ``package.module:factory``).
MODELS = ("varying", "pooled")
#: ``--wind-bins`` given without a number: :data:`vivbench.analysis.WIND_BINS` bins (not a string, which argparse
#: would pass through the option's type).
DEFAULT_WIND_BINS = ("WIND_BINS",)
#: Former names of ``--model`` values, refused with the current name.
RENAMED_MODELS = {"sindy": "pooled"}


def _model_name(text: str) -> str:
    """The ``--model`` value; a former name is refused with a message naming the current one."""
    if text in RENAMED_MODELS:
        raise argparse.ArgumentTypeError(f"{text!r} is now named {RENAMED_MODELS[text]!r}")
    if text not in MODELS and ":" not in text:
        raise argparse.ArgumentTypeError(f"must be one of {', '.join(MODELS)} or a package.module:factory; got {text!r}")
    return text


def _model_classes(text: str) -> tuple[str, ...]:
    """The ``--model-classes`` value: distinct names among the selection's model classes."""
    from vivbench.analysis.selection import MODEL_CLASSES

    names = tuple(x.strip() for x in text.split(","))
    if not names or len(set(names)) != len(names) or not set(names) <= set(MODEL_CLASSES):
        raise argparse.ArgumentTypeError(f"must be distinct names among {','.join(MODEL_CLASSES)}; got {text!r}")
    return names


def run(args) -> int:
    from vivbench.io.result import list_results, select_results

    weights = _wind_weights(args.wind_weights)  # a bad option is reported before any file is read
    k = args.min_time_constants
    if k is not None and not (math.isfinite(k) and k >= 0):
        raise InputError(f"--min-time-constants must be a number of time constants >= 0 (0: no restriction); got {k!r}")
    if isinstance(args.wind_bins, int) and args.wind_bins < 0:
        raise InputError(f"--wind-bins must be an integer >= 0 (0: the campaign-wide test alone); got {args.wind_bins!r}")
    args.wind_smoothing_grid = _seconds_list(args.wind_smoothing_grid)
    results_dir = Path(args.results)
    files = list_results(results_dir)
    if args.events is not None:
        if args.out is None or Path(args.out).resolve() == results_dir.resolve():
            raise InputError(f"{results_dir}: --events pools part of the campaign; give --out another directory, so "
                             "that its model and regimes do not replace those of the whole campaign")
        files = select_results(files, args.events)
    out_dir = Path(args.out) if args.out else results_dir
    ds = _pool(files, args, weights, out_dir, results_dir, label=args.events)
    if args.split_at_change:
        event = _located_change(ds)
        ids = [Path(f).name.removesuffix(".identify.nc") for f in files]
        if event not in ids[1:]:
            print("vivbench pool: no change located: the campaign is not split")
            return 0
        i = ids.index(event)
        for name, part, label in ((f"before_{event}", files[:i], f"{ids[0]}..{ids[i - 1]}"),
                                  (f"from_{event}", files[i:], f"{event}..{ids[-1]}")):
            _pool(part, args, weights, out_dir / name, results_dir, label=label)
    return 0


def _pool(files, args, weights, out_dir: Path, results_dir: Path, *, label: str | None):
    """Fit the campaign model of ``args`` to ``files`` (``label``: which of the campaign's events they are, None for
    all), write its regimes and model into ``out_dir`` and report; returns the regimes' dataset."""
    from vivbench.models.campaign import PooledSINDy
    from vivbench.analysis.selection import varying_selection
    from vivbench.analysis.pool import pool_results
    from vivbench.io.campaign_model import MODEL_NAME, write_campaign_regimes
    from vivbench.models.protocol import model_settings_text

    campaign = Path(args.campaign) if args.campaign else None
    smoothing = 0.0
    if args.model not in MODELS:
        from vivbench.validate.methods import check_method_spec, resolve_method

        # A user's campaign model of the protocol (docs/methods.md), fitted in place like the built-in ones.
        model = resolve_method(check_method_spec(args.model))
        smoothing = 0.0 if args.wind_smoothing is None else args.wind_smoothing
    elif args.model == "varying":
        # Options given on the command line are pinned; the others of VARYING_OPTIONS are chosen from the
        # campaign's held-out evidence (vivbench.analysis.selection).
        extra = {k: v for k, v in (("yaw_degree", args.yaw_degree), ("wind_smoothing_s", args.wind_smoothing),
                                   ("wind_smoothing_grid", args.wind_smoothing_grid), ("wind_input", args.wind_input),
                                   ("wind_weights", weights), ("penalty_choice", args.penalty_choice),
                                   ("model_classes", args.model_classes))
                 if v is not None}
        if args.min_time_constants is not None:
            extra["min_time_constants"] = args.min_time_constants or None  # 0: no restriction
        if args.wind_bins is DEFAULT_WIND_BINS:
            from vivbench.analysis import WIND_BINS

            extra["wind_bins"] = WIND_BINS
        elif args.wind_bins is not None:
            extra["wind_bins"] = args.wind_bins or None  # 0: the campaign-wide null test alone
        model = varying_selection(n_folds=args.folds, criterion=args.criterion, n_perturbations=args.perturbations,
                                  seed=args.seed, workers=args.workers, n_bootstrap=args.bootstrap,
                                  block_s=args.block, agreement=args.agreement, tau=args.tau, **extra)
    else:
        model = PooledSINDy(n_bootstrap=args.bootstrap, block_s=args.block, agreement=args.agreement, tau=args.tau,
                            seed=args.seed)
        smoothing = 0.0 if args.wind_smoothing is None else args.wind_smoothing
    ds = pool_results(files, model, campaign=campaign, wind_smoothing_s=smoothing)  # fits ``model`` in place
    if args.model == "varying" and not ds.attrs["wind_yaw"]:
        print(f"vivbench pool: {results_dir}: the results store no wind yaw (identified before vivbench stored it): "
              "the varying model was fitted without its yaw covariate; identify again or give --campaign",
              file=sys.stderr)
    out_dir.mkdir(parents=True, exist_ok=True)
    out = write_campaign_regimes(ds, out_dir)
    # The fitted model itself, for forecast, validate and the report (the model protocol's load).
    model_out = model.save(out_dir / MODEL_NAME)
    if ds.attrs.get("note"):
        print(f"vivbench pool: {ds.attrs['note']}", file=sys.stderr)
    if args.model == "varying":
        print(f"vivbench pool: chose {model.chosen_} from the campaign's own evidence; " + model.evidence_text())
    shape = model_settings_text(model)
    chosen = "" if label is None else f" ({label})"
    print(f"wrote {out}: {len(files)} events{chosen}, {ds.sizes['window_all']} windows, {shape}, "
          f"regime coverage (identifiable) {ds.attrs['coverage']:.3f}")
    if ds.attrs.get("model_change_detected"):
        print(f"vivbench pool: the campaign model changes with time (refitted before/after each split, permutation "
              f"p = {ds.attrs['model_change_p_value']:.3f}, most likely from {ds.attrs['model_change_event']} on): it "
              "averages over a change the wind does not carry" + _sides(files, ds.attrs["model_change_event"]),
              file=sys.stderr)
    elif ds.attrs["change_detected"]:
        print(f"vivbench pool: the events' residuals change with time (permutation p = {ds.attrs['change_p_value']:.3f}, "
              f"most likely from {ds.attrs['change_event']} on): the campaign model averages over a change the "
              "wind does not carry" + _sides(files, ds.attrs["change_event"]), file=sys.stderr)
    for key, what in (("change_flagged_events", "after the change whose own offset departs from the events' before it"),
                      ("offset_flagged_events", "whose linear offset departs from the other events' of its stratum"),
                      ("offset_not_assessed_events", "whose offset was not tested (no finite offset, or fewer "
                       "than 4 events of its stratum)")):
        if flagged := json.loads(ds.attrs.get(key, "[]")):
            print(f"vivbench pool: events {what}: {', '.join(flagged)}", file=sys.stderr)
    print(f"wrote {model_out}: the fitted campaign model (vivbench.analysis.load_campaign_model)")
    return ds


def _located_change(ds) -> str:
    """The first event after the change that pool's scans located ("" without one): the model's own scan's, else
    the residuals'."""
    if ds.attrs.get("model_change_detected"):
        return str(ds.attrs["model_change_event"])
    return str(ds.attrs["change_event"]) if ds.attrs["change_detected"] else ""


def _sides(files, event_id: str) -> str:
    """How to pool each side of a change located from ``event_id`` on ("" when it is not among ``files``)."""
    ids = [Path(f).name.removesuffix(".identify.nc") for f in files]
    if event_id not in ids or ids.index(event_id) == 0:
        return ""
    before = ids[ids.index(event_id) - 1]
    return (f"; pool each side alone for its own model and regimes (--events ..{before} and --events {event_id}.., "
            "each with its own --out)")


def _wind_weights(text: str | None):
    """``--wind-weights``: None (the model's default), a named choice, or comma-separated numbers."""
    if text is None or text in ("modal", "equal"):
        return text
    from vivbench.models.wind_weights import check_wind_weights

    try:
        weights = tuple(float(x) for x in text.split(","))
        check_wind_weights(weights)
    except ValueError:  # InputError is one
        raise InputError(f"--wind-weights must be modal, equal or comma-separated numbers >= 0 with a "
                         f"positive sum (one per section); got {text!r}") from None
    return weights


def _seconds_list(text: str | None) -> tuple[float, ...] | None:
    """``--wind-smoothing-grid``: None, or comma-separated seconds >= 0."""
    if text is None:
        return None
    try:
        grid = tuple(float(x) for x in text.split(","))
    except ValueError:
        grid = ()
    if not grid or not all(math.isfinite(x) and x >= 0 for x in grid):
        raise InputError(f"--wind-smoothing-grid must be comma-separated seconds >= 0 (e.g. 10,30,60); got {text!r}")
    return grid


def register(sub) -> None:
    s = sub.add_parser("pool", help="fit one model to a whole campaign's results and label every window with it")
    s.add_argument("results", help="directory of <event_id>.identify.nc")
    s.add_argument("--out", default=None, help="output directory (default: the results directory)")
    s.add_argument("--events", default=None, metavar="SPEC",
                   help="pool only these events: comma-separated ids and ranges in the campaign's order (E003, "
                        "E007.. from E007 on, ..E006, E002..E005), e.g. each side of a change the scan located; "
                        "needs --out")
    s.add_argument("--split-at-change", action="store_true",
                   help="where the change scan locates a change, also pool the events before it and those from it "
                        "on, each into a directory of its own under the output directory (before_<event>, "
                        "from_<event>): a model and regimes of each period")
    s.add_argument("--model", type=_model_name, default="varying", metavar="{varying,pooled,MODULE:FACTORY}",
                   help="campaign model: varying (default: chosen from the campaign's held-out evidence among "
                        "VaryingCoefficientSINDy's options, penalised spline curves in U with the wind's yaw that "
                        "follow a lock-in bell no polynomial in U does, and the classes of --model-classes) or "
                        "pooled (PooledSINDy, sparse regression on the 69-term library, the paper's class), or "
                        "package.module:factory, a user's campaign model of the protocol (docs/methods.md) that "
                        "the factory returns unfitted")
    s.add_argument("--model-classes", default=None, type=_model_classes, metavar="varying,pooled",
                   help="with --model varying: the classes of campaign model the held-out choice is made among "
                        "(default varying,pooled: PooledSINDy on the same smoothed wind is a candidate beside the "
                        "varying model's options, and the lower held-out loss decides between them; varying: the "
                        "varying model alone)")
    s.add_argument("--campaign", default=None,
                   help="directory of the results' event files, only for results identified before the result "
                        "stored the wind's yaw: their yaw is then measured from the events' anemometers")
    s.add_argument("--yaw-degree", type=int, default=None, choices=(0, 1, 2),
                   help="with --model varying: powers of sin^2(yaw) in the curves (default: 0, 1 or 2, chosen from "
                        "the campaign's held-out evidence when the results store the yaw, 2 tried only where 1 is "
                        "chosen over 0; else 0)")
    s.add_argument("--wind-input", default=None, choices=("mean", "section", "additive", "sum"),
                   help="with --model varying: the wind of the curves: the mean over the sections (default), each "
                        "section's own, or every section's wind and yaw with a curve each, summed like the truth's "
                        "forces (additive; its basis, penalty and yaw chosen as for the others, a fit several times "
                        "slower), or "
                        "every section's wind with one curve shared by all, weighted by --wind-weights and summed (sum: "
                        "the truth's form where the sections feel different winds, e.g. along a long span; where the "
                        "deck feels one smooth wind and each anemometer adds its own turbulence, the mean averages "
                        "that turbulence down and fits closer; docs/limitations.md)")
    s.add_argument("--wind-weights", default=None, metavar="equal|modal|W1,W2,...",
                   help="with --model varying and the mean wind (or the sum): the sections' weights in it: modal (default, a "
                        "prior: each section's share of the mode's energy, sum of A_k^2, the weights of the averaged "
                        "truth when the sections' tributary lengths are equal), equal (the plain mean), or one "
                        "number per section (e.g. L_k phi_k^2 from the bridge's drawings)")
    s.add_argument("--penalty-choice", choices=("cv", "least", "loeo"), default=None,
                   help="with --model varying: the curves' roughness penalty (default: cv or least, chosen from the "
                        "campaign's held-out evidence): cv (the 5-fold "
                        "cross-validated error's minimum), least (the least penalty whose leave-one-event-out error "
                        "is not significantly above the best one's) or loeo (the leave-one-event-out error's "
                        "minimum)")
    s.add_argument("--wind-smoothing", type=float, default=None,
                   help="Gaussian smoothing of the mean wind (and yaw) in time, standard deviation in s, a lower "
                        "cut-off against the point anemometer's slow turbulence (default: 30 s with --model varying, "
                        "a stated prior; 0 with --model pooled)")
    s.add_argument("--wind-smoothing-grid", default=None, metavar="S1,S2,...",
                   help="with --model varying: candidate smoothings (s, e.g. 10,30,60) that replace the prior (30 s, "
                        "or --wind-smoothing) for every model where the simplest candidate's cross-validated dA/dt "
                        "error over at least 5 folds of events is lower by more than one standard error; an option, "
                        "not the default: it broke the verdict's promise on an evaluation draw (docs/limitations.md)")
    s.add_argument("--folds", type=int, default=5,
                   help="with --model varying: folds of whole events for the held-out choice of the options not "
                        "given here (yaw degree, penalty choice; default 5, one event per fold with fewer events)")
    s.add_argument("--criterion", choices=("output", "derivative"), default="output",
                   help="held-out criterion of that choice: output (each held-out event's envelope simulated "
                        "from its start under its measured wind; default) or derivative (its dA/dt)")
    s.add_argument("--perturbations", type=int, default=2,
                   help="with --model varying: refits on winds perturbed by their estimated error whose regimes a "
                        "flagged window must match (default 2; 0: none)")
    s.add_argument("--min-time-constants", type=float, default=None,
                   help="with --model varying: flag no limit regime (3, 4) in an event shorter than this many "
                        "envelope time constants, read from the chosen model's regime-1 windows (default "
                        "LIMIT_TIME_CONSTANTS, 5, a stated prior; 0: no such restriction)")
    s.add_argument("--wind-bins", type=int, nargs="?", const=DEFAULT_WIND_BINS, default=None, metavar="N",
                   help="with --model varying: also test the dynamics by wind, in N bins of the measured wind "
                        "(equal shares of the samples; WIND_BINS, 6, without N): a window is flagged only where "
                        "the chosen model beats the quasi-steady map on held-out events in its bin (default: off, "
                        "the campaign-wide test alone; 0: off)")
    s.add_argument("--workers", type=int, default=1, help="local processes for the held-out fits (default 1)")
    s.add_argument("--bootstrap", type=int, default=100, help="block-bootstrap replicates (default 100)")
    s.add_argument("--block", type=float, default=300.0, help="bootstrap block length, s (default 300)")
    s.add_argument("--agreement", type=float, default=0.9,
                   help="share of replicates that must agree on a window's regime for it to count as identifiable")
    s.add_argument("--tau", type=float, default=0.2, help="regime threshold (docs/concepts.md (regimes))")
    s.add_argument("--seed", type=int, default=0, help="bootstrap seed")
    s.set_defaults(func=run)
