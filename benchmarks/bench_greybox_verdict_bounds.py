"""Grey-box window verdicts of a saved fit: clipped vs reflected bound draws, with and without the reference.

Usage: python benchmarks/bench_greybox_verdict_bounds.py GREYBOX_OUT RESULTS_DIR CAMPAIGN_DIR
(GREYBOX_OUT holds the greybox.nc of `vivbench greybox RESULTS_DIR`, fitted with the default 30 s wind
smoothing; RESULTS_DIR holds the campaign model of `vivbench pool`, the verdicts' reference.)
Prints, per bound rule, the share of flagged windows with the true regime, their count and the coverage,
with the draws alone and with the reference's point regime required to agree, and the reference's own
point-regime accuracy.
"""

import sys

import numpy as np

from vivbench.analysis.pool import (
    campaign_model_file,
    load_campaign_model,
    records_from_results,
)
from vivbench.cli.common import event_paths
from vivbench.core.regime import regime_rule
from vivbench.io.event import read_event
from vivbench.io.result import list_results, read_result
from vivbench.models.greybox import GreyBoxRefit
from vivbench.regimes.greybox import greybox_window_verdicts
from vivbench.regimes.truth import truth_window_regimes
from vivbench.regimes.varying import window_order_stats

gb, res, camp = sys.argv[1:4]
m = GreyBoxRefit.load(f"{gb}/greybox.nc"); files = list_results(res); recs = records_from_results(files, wind_smoothing_s=30.0)
cm = load_campaign_model(campaign_model_file(res))
truths = {str((t := read_event(p)).attrs["event_id"]): t["truth"].ds for p in event_paths([camp])}
out = {b: [[], [], [], []] for b in ("clip", "reflect")}
for f, rec in zip(files, recs):
    ds = read_result(f, ["window_start", "window_end"]); s, e = ds["window_start"].values, ds["window_end"].values
    T = truth_window_regimes(truths[rec.event_id], s, e, tau=0.2)
    R, c1, nv = window_order_stats(cm.order_contributions(rec), rec.A, rec.t, s, e)
    C = np.where(nv > 0, regime_rule(np.nan_to_num(R), c1, 0.2), 0)
    for b in out:
        v = greybox_window_verdicts(m, rec, s, e, bounds=b)
        for L, x in zip(out[b], (v["regime"], v["identifiable"], T, C)): L.append(x)
for b, L in out.items():
    I, F, T, C = map(np.concatenate, L)
    for name, FF in (("alone", F), ("consensus", F & (C == I))):
        mk = FF & (T > 0) & (I > 0)
        print(gb.split('/')[-1], b, name, "precision %.3f n_flag %d coverage %.3f" % (np.mean(I[mk] == T[mk]), mk.sum(), np.mean(FF & (I > 0))), flush=True)
    mk = (T > 0) & (C > 0); print("  campaign model point regime accuracy %.3f" % np.mean(C[mk] == T[mk]))
