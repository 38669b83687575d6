"""``vivbench refit``: output-error (CasADi multiple-shooting) refit of one identification result."""

from __future__ import annotations

import csv
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING
from vivbench.core.errors import InputError

if TYPE_CHECKING:
    import numpy as np

_CSV_COLUMNS = ("equation", "feature", "in_support", "sindy", "lsq", "refit", "truth")
_ORDER_COLUMNS = ("equation", "order", "sindy", "lsq", "refit", "truth")


def _load_result(path: str):
    from vivbench.io.result import read_result

    return read_result(path)


def _truth_coef(path: str, event_id: str):
    """The event file's exact coefficient matrix, or None when it has none (a field event or a
    truth outside the library, e.g. the realistic generator mode)."""
    from vivbench.io.event import event_arrays, read_event

    tree = read_event(path)
    if str(tree.attrs["event_id"]) != event_id:
        raise InputError(f"{path}: event {tree.attrs['event_id']!r} does not match the result's {event_id!r}")
    return event_arrays(tree).get("coef")


def _json_value(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None if math.isnan(v) else ("inf" if v > 0 else "-inf")
    return v


def _own_section_mask(spec: str, features) -> np.ndarray:
    """Support (S, 23 S) from section-generic monomials, e.g. "U^2, A, A U": equation k uses section k's terms."""
    import re

    import numpy as np

    features = [str(f) for f in features]
    S = len(features) // 23
    mask = np.zeros((S, len(features)), dtype=bool)
    terms = [t.strip() for t in spec.split(",") if t.strip()]
    if not terms:
        raise InputError(f"--terms {spec!r}: give comma-separated monomials such as 'U^2, A, A U, A^3 U'")
    for term in terms:
        if not re.fullmatch(r"(A(\^[123])?)?\s*(U(\^[1-5])?)?", term):
            raise InputError(f"--terms: {term!r} is not a monomial A^i U^j (i <= 3, j <= 5), e.g. 'A^2 U^3'")
        for k in range(S):
            name = re.sub(r"\s+", " ", term.replace("A", f"A{k + 1}").replace("U", f"U{k + 1}"))
            if name not in features:
                raise InputError(f"--terms: {term!r} is not in the library")
            mask[k, features.index(name)] = True
    return mask


DEPRECATION = ("the refit on an identified support is deprecated (issue 14): on a realistic VIV segment "
               "(69 terms per equation, rank deficient) neither Gauss-Newton nor IPOPT gives a model that simulates "
               "the segment (README, benchmarks/study_refit.py); for reference coefficients use "
               "`vivbench greybox RESULTS_DIR --out DIR`. True or small supports (--support truth, --terms) are "
               "refitted by Gauss-Newton.")


def run(args) -> int:
    from vivbench.models.refit import RefitConfig, refit_event
    from vivbench.io.netcdf import atomic_path


    if args.support is None and not args.terms:
        # no default: the identified support, the old default, is deprecated (issue 14)
        raise InputError(f"{args.result}: say which support to refit: --terms 'U^2, A, A U' (a small generic support), "
                         "--support truth (needs --event) or --support window|identified (deprecated: use "
                         "`vivbench greybox` for reference coefficients)")
    if args.support is not None and args.terms:
        raise InputError(f"{args.result}: give --support or --terms, not both")
    result = _load_result(args.result)
    event_id = str(result.attrs.get("event_id", Path(args.result).name.split(".")[0]))
    truth = _truth_coef(args.event, event_id) if args.event else None
    if args.support == "truth" and truth is None:
        if args.event:
            raise InputError(f"{args.event}: no /truth/coef for --support truth (a field event or a truth outside the library)")
        raise InputError("--support truth needs --event EVENT.nc (the event file with /truth/coef)")
    if args.event and truth is None:
        print(f"vivbench refit: {args.event} has no /truth/coef (a field event or a truth outside the library): "
              "no true-model comparison", file=sys.stderr)
    config = RefitConfig(shooting_interval=args.shooting_interval, substeps=args.substeps, max_iter=args.max_iter,
                         tol=args.tol, ridge=args.ridge, hessian=args.hessian,
                         free_initial_state=args.free_initial_state, max_wall_time=args.max_wall_time, solver=args.solver)
    support = _own_section_mask(args.terms, result["feature"].values) if args.terms else args.support
    try:
        ev = refit_event(result, t0=args.t0, t1=args.t1, support=support, truth_coef=truth, config=config)
    except InputError as exc:  # a bad segment or support: name the result; anything else is a bug
        raise InputError(f"{args.result}: {exc}") from None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, columns, rows in ((f"refit_{event_id}.csv", _CSV_COLUMNS, ev.rows()),
                                (f"refit_orders_{event_id}.csv", _ORDER_COLUMNS, ev.order_rows())):
        with atomic_path(out / name) as tmp, open(tmp, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
            writer.writeheader()
            for row in rows:
                writer.writerow({k: (f"{v:.10g}" if isinstance(v, float) else v) for k, v in row.items()})
    summary = {k: _json_value(v) for k, v in ev.summary().items()}
    with atomic_path(out / "summary.json") as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
    print(f"refit {event_id} [{ev.t0:g}, {ev.t1:g}] s on the {ev.support_kind} support: {ev.fit.solver} "
          f"{ev.fit.status} after {ev.fit.iterations} iterations; wrote {out}")
    if ev.support_kind in ("identified", "window"):
        # after the work, so that bad input still fails with one line
        print(f"vivbench refit: {DEPRECATION}", file=sys.stderr)
    return 0


def register(sub) -> None:
    s = sub.add_parser("refit", help="output-error refit of library coefficients on a support (CasADi, Gauss-Newton; identified supports deprecated: use greybox)")
    s.add_argument("result", help="identification result <event_id>.identify.nc")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--event", default=None,
                   help="the event file, for the truth coefficients and support (an event without /truth/coef, "
                        "e.g. of the realistic generator mode, is refitted without the true-model comparison)")
    s.add_argument("--t0", type=float, default=None, help="segment start, s (default: start of the grid)")
    s.add_argument("--t1", type=float, default=None, help="segment end, s (default: end of the grid)")
    s.add_argument("--support", default=None, choices=("identified", "window", "truth"),
                   help="no default: give this or --terms. identified (deprecated): union over the windows in force "
                        "in the segment; window (deprecated): the window in force at t0; truth: the exact "
                        "coefficients' nonzeros (needs --event)")
    s.add_argument("--terms", default=None,
                   help="instead of --support: section-generic monomials, each equation using its own section's, "
                        "e.g. 'U^2, A, A U, A^2 U, A^3 U'")
    s.add_argument("--shooting-interval", type=float, default=20.0, help="shooting interval, s (default 20)")
    s.add_argument("--substeps", type=int, default=1, help="RK4 steps per grid step (default 1)")
    s.add_argument("--max-iter", type=int, default=200,
                   help="IPOPT iterations, or Gauss-Newton linearisations, at most (default 200)")
    s.add_argument("--solver", default="gauss-newton", choices=("gauss-newton", "ipopt"),
                   help="gauss-newton (default): Levenberg-Marquardt on the exact Gauss-Newton matrix; ipopt: the "
                        "constrained NLP (slow and does not converge on large supports; kept for comparison)")
    s.add_argument("--tol", type=float, default=None,
                   help="IPOPT tolerance (default 1e-10), or the Gauss-Newton relative cost decrease (default 1e-6)")
    s.add_argument("--ridge", type=float, default=0.0, help="ridge weight on the scaled coefficients (default 0)")
    s.add_argument("--hessian", default="auto", choices=("auto", "exact", "limited-memory"),
                   help="IPOPT Hessian (auto: exact up to 24 supported terms, limited-memory above)")
    s.add_argument("--free-initial-state", action="store_true",
                   help="fit the initial state too (default: fixed to the first measured A, as in the scoring)")
    s.add_argument("--max-wall-time", type=float, default=None, help="solver wall-clock limit, s (default none)")
    s.set_defaults(func=run)
