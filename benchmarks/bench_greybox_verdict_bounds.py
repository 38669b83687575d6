"""Grey-box window verdicts of a saved fit recomputed with clipped vs reflected bound draws, scored on the truth.

Usage: python benchmarks/bench_greybox_verdict_bounds.py GREYBOX_OUT RESULTS_DIR CAMPAIGN_DIR [WIND_SMOOTHING_S]
(GREYBOX_OUT holds the greybox.nc of `vivbench greybox`; the wind smoothing must be the run's, default 30 s.)
Prints precision of the flagged windows (share with the true regime), their count, coverage, accuracy.
"""

import sys

import numpy as np

from vivbench.analysis.pool import records_from_results
from vivbench.cli.common import event_paths
from vivbench.io.event import read_event
from vivbench.io.result import list_results, read_result
from vivbench.models.greybox import GreyBoxRefit
from vivbench.regimes.greybox import greybox_window_verdicts
from vivbench.regimes.truth import truth_window_regimes
from vivbench.validate.recovery import regime_scores

gb, res, camp = sys.argv[1:4]
ws = float(sys.argv[4]) if len(sys.argv) > 4 else 30.0
m = GreyBoxRefit.load(f"{gb}/greybox.nc")
files = list_results(res)
kw = {"wind_smoothing_s": ws}
recs = records_from_results(files, **kw)
truths = {str((t := read_event(p)).attrs["event_id"]): t["truth"].ds for p in event_paths([camp])}
for bounds in ("clip", "reflect"):
    I, T, F = [], [], []
    for f, rec in zip(files, recs):
        ds = read_result(f, ["window_start", "window_end"]); s, e = ds["window_start"].values, ds["window_end"].values
        v = greybox_window_verdicts(m, rec, s, e, bounds=bounds)
        I.append(v["regime"]); F.append(v["identifiable"]); T.append(truth_window_regimes(truths[rec.event_id], s, e, tau=0.2))
    I, T, F = np.concatenate(I), np.concatenate(T), np.concatenate(F)
    sc = regime_scores(I, T, F); mk = F & (T > 0) & (I > 0)
    print(gb, bounds, "precision_identifiable %.3f n_flag %d coverage %.3f accuracy_all %.3f" % (np.mean(I[mk] == T[mk]), mk.sum(), sc["coverage"], sc["accuracy_all"]), flush=True)
