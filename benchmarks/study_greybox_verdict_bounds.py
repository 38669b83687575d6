"""Grey-box window verdicts of a saved fit: clipped vs reflected bound draws, with and without the reference.

Run: ``python benchmarks/run_study.py greybox_verdict_bounds GREYBOX_OUT RESULTS_DIR CAMPAIGN_DIR``
(GREYBOX_OUT holds the greybox.nc of ``vivbench greybox RESULTS_DIR``, fitted with the default 30 s
wind smoothing; RESULTS_DIR holds the campaign model of ``vivbench pool``, the verdicts'
reference; CAMPAIGN_DIR the events with their truth). Per bound rule (``clip``, ``reflect``) and
per verdict (the draws ``alone``; ``consensus``: the reference's point regime must agree too):
the share of flagged windows with the true regime (``precision``), their count and the
coverage; and the reference's own point-regime accuracy. Nothing is asserted.
"""

from __future__ import annotations

import argparse

import numpy as np

from vivbench.analysis.pool import campaign_model_file, load_campaign_model, records_from_results
from vivbench.cli.common import event_paths
from vivbench.core.regime import regime_rule
from vivbench.io.event import read_event
from vivbench.io.result import list_results, read_result
from vivbench.models import window_order_stats
from vivbench.models.greybox import GreyBoxRefit
from vivbench.regimes.greybox import greybox_window_verdicts
from vivbench.regimes.truth import truth_window_regimes


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("greybox", help="directory of the greybox.nc of vivbench greybox")
    parser.add_argument("results", help="identification results with the campaign model of vivbench pool")
    parser.add_argument("campaign", help="the events, with their truth")
    args = parser.parse_args(argv)
    model = GreyBoxRefit.load(f"{args.greybox}/greybox.nc")
    files = list_results(args.results)
    records = records_from_results(files, derivative=None, wind_smoothing_s=30.0)
    reference = load_campaign_model(campaign_model_file(args.results))
    truths = {str((t := read_event(p)).attrs["event_id"]): t["truth"].ds for p in event_paths([args.campaign])}
    parts = {b: {"regime": [], "flag": [], "truth": [], "reference": []} for b in ("clip", "reflect")}
    for f, rec in zip(files, records):
        ds = read_result(f, ["window_start", "window_end"])
        start, end = ds["window_start"].values, ds["window_end"].values
        truth = truth_window_regimes(truths[rec.event_id], start, end, tau=0.2)
        R, c1, nv = window_order_stats(reference.order_contributions(rec), rec.A, rec.t, start, end)
        point = np.where(nv > 0, regime_rule(np.nan_to_num(R), c1, 0.2), 0)
        for bounds, part in parts.items():
            v = greybox_window_verdicts(model, rec, start, end, bounds=bounds)
            for key, x in zip(part, (v["regime"], v["identifiable"], truth, point)):
                part[key].append(x)
    out: dict = {}
    for bounds, part in parts.items():
        regime, flag, truth, point = (np.concatenate(part[k]) for k in ("regime", "flag", "truth", "reference"))
        for name, flagged in (("alone", flag), ("consensus", flag & (point == regime))):
            scored = flagged & (truth > 0) & (regime > 0)
            out[f"{bounds}, {name}"] = {"precision": float(np.mean(regime[scored] == truth[scored])),
                                        "n_flagged": int(scored.sum()),
                                        "coverage": float(np.mean(flagged & (regime > 0)))}
            print(bounds, name, out[f"{bounds}, {name}"], flush=True)
        both = (truth > 0) & (point > 0)
        out["reference point-regime accuracy"] = float(np.mean(point[both] == truth[both]))
    return out


if __name__ == "__main__":
    main()
