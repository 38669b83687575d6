"""Truth substitution for the grey-box refit: which input errors cost a_k1, and where the fit's minimum lies.

Run: ``.venv/bin/python benchmarks/study_greybox_substitution.py --results R --campaign CAMP
[--substitute none,U,A,U+A] [--truth-start]``. For every entry of ``--substitute`` the
grey-box model is refitted (defaults of ``vivbench greybox``: campaign-model
warm start, multi-start, GCV penalty) on the measured records with the named
inputs replaced by the truth's (``/truth`` U, the deck's felt wind, and A,
interpolated onto the measured grid, measured gaps kept; a replaced U is not
smoothed). With ``--truth-start`` every case is also refitted from the
truth's own curves (one start, the fixed penalty 0.3, as is the default fit
for comparison then): a start-independent minimum gives both the same a_k1;
the data RSS (unpenalised, ``band_info["rss"]``) says which minimum the data
prefer. Scored like ``vivbench greybox --campaign``: relative RMS error of the
reference section's a_k1 over the lock-in winds, dA/dt from the curves, band
coverage. Validation only (reads the truth); nothing is asserted.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_greybox import _bridge  # noqa: E402

from vivbench.analysis import smooth_wind  # noqa: E402
from vivbench.analysis.greybox import campaign_warm_start  # noqa: E402
from vivbench.analysis.pool import curve_wind_grid, records_from_results  # noqa: E402
from vivbench.core.terms import reference_section  # noqa: E402
from vivbench.io.event import list_events, read_event  # noqa: E402
from vivbench.io.result import list_results  # noqa: E402
from vivbench.models.greybox import GreyBoxRefit  # noqa: E402
from vivbench.validate.campaign import event_truth_curves  # noqa: E402
from vivbench.validate.metrics import curve_errors  # noqa: E402


def _substitute(rec, truth, what):
    new = {}
    for name in what:
        src = truth[name].values
        x = np.stack([np.interp(rec.t, truth["time"].values, src[:, k], left=np.nan, right=np.nan)
                      for k in range(src.shape[1])], axis=1)
        new[name] = np.where(np.isfinite(getattr(rec, name)), x, np.nan)
    return dataclasses.replace(rec, **new)


def main(argv=None) -> list:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", required=True)
    p.add_argument("--campaign", required=True)
    p.add_argument("--substitute", default="none,U,A,U+A", help="comma list of none, U, A, U+A")
    p.add_argument("--truth-start", dest="truth_start", action="store_true",
                   help="also refit every case from the truth's curves (fixed penalty 0.3, the default fit too)")
    args = p.parse_args(argv)
    results, camp = Path(args.results), Path(args.campaign)
    raw = records_from_results(list_results(results), derivative=None)  # the grey-box fits envelopes, not dA/dt
    truths = {str(t.attrs["event_id"]): t["truth"].ds for t in (read_event(f) for f in list_events(camp))}
    tc = tw = None
    U, A, X = [], [], []
    for tr in truths.values():
        if tc is None:
            tc, tw = event_truth_curves(tr)
        U.append(tr["U"].values)
        A.append(tr["A"].values)
        X.append(tr["regime"].values >= 2)
    U, A, X = np.concatenate(U), np.concatenate(A), np.concatenate(X)
    truth_start = xr.Dataset({"curves": (("equation", "order", "wind"), tc)},
                             coords={"equation": [f"S{k + 1}" for k in range(tc.shape[0])], "order": np.arange(4),
                                     "wind": tw})
    bridge = _bridge(camp)
    rows = []
    for case in args.substitute.split(","):
        what = tuple(x for x in case.split("+") if x and x != "none")
        recs = [_substitute(r, truths[r.event_id], what) for r in raw]
        recs = [smooth_wind(r, 0.0 if "U" in what else 30.0) for r in recs]
        warm, _ = campaign_warm_start(results, curve_wind_grid(np.concatenate([r.U.ravel() for r in recs])))
        fits = [("default", {"warm_start": warm})]
        if args.truth_start:
            fits = [("default, penalty 0.3", {"warm_start": warm, "penalty_grid": None}),
                    ("truth start, penalty 0.3", {"warm_start": truth_start, "penalty_grid": None, "n_starts": 1})]
        for name, kw in fits:
            t0 = time.perf_counter()
            m = GreyBoxRefit(bridge=bridge, **kw).fit(recs)
            cur = m.curves()
            w = cur["wind"].values
            err = curve_errors(cur["curves"].values, w, tc, tw, U, A, X)
            k = reference_section(m.n_sections_)
            lock = err["lock_in_wind"][k]
            g = (w >= lock[0]) & (w <= lock[1])
            at = np.interp(w, tw, tc[k, 1])
            lo, hi = cur["curves_lower"].values[k, 1, g], cur["curves_upper"].values[k, 1, g]
            row = {"substitute": case, "fit": name, "a_k1_error": err["linear"][k], "dAdt_error": err["total"][k],
                   "band_coverage": float(np.mean((at[g] >= lo) & (at[g] <= hi))),
                   "rss": m.fit_info_["band_info"]["rss"], "penalty": m.penalty_, "start": m.fit_info_["start"],
                   "seconds": time.perf_counter() - t0}
            print(json.dumps(row), flush=True)
            rows.append(row)
    return rows


if __name__ == "__main__":
    main()
