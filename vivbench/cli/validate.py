"""``vivbench validate``: score identification results against a synthetic campaign's truth."""

from __future__ import annotations

import math
import sys


def run(args) -> int:
    from vivbench.validate import validate_campaign, write_validation

    v = validate_campaign(args.campaign, args.results, clusters_csv=args.clusters,
                          forecasts_dir=args.forecasts, tau=args.tau,
                          active_share=args.active_share)
    for path, reason in sorted(v["skipped"].items()):
        print(f"vivbench validate: {path}: {reason}", file=sys.stderr)
    written = write_validation(v, args.out)
    s = v["summary"]

    def f(key):
        x = s.get(key, math.nan)
        return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.3f}"

    support = (f"support recall {f('support_recall_terms')} terms / {f('support_recall_pooled_terms')} "
               f"section-pooled / {f('support_recall_orders')} orders" if v["support"] is not None
               else f"support {v['support_note']}")
    print(f"validate: {s['n_events']} events, {s['n_window_equations']} window-equations; regime coverage "
          f"{f('regime_coverage')}, accuracy {f('regime_accuracy_identifiable')} identifiable / "
          f"{f('regime_accuracy_all')} all; dA/dt rel. error on the true (A, U): median over windows "
          f"{f('median_rhs_error_true_AU_active')} (active), energy-weighted {f('energy_rhs_error_true_AU')}"
          + (f", on the measured (A, U) {f('median_rhs_rel_error_active')} (active)" if v["rhs"] is not None else "")
          + f"; {support}")
    if "campaign_model_regime_coverage" in s:
        curves = v["campaign_model"]["curves"]
        curve_text = (f"curve error over lock-in ({curves['reference_equation']}): a_k1 {f('campaign_model_curve_error_linear')}, "
                      f"total {f('campaign_model_curve_error_total')}" if curves.get("scored")
                      else f"curves not scored against the truth's curves: {curves.get('reason')}")
        curve_text += f"; curve dA/dt error energy-weighted {f('campaign_model_curve_error_energy')}"
        print(f"campaign model (vivbench pool): regime coverage {f('campaign_model_regime_coverage')}, accuracy "
              f"{f('campaign_model_regime_accuracy_identifiable')} identifiable / {f('campaign_model_regime_accuracy_all')} all; "
              f"dA/dt rel. error on the true (A, U): median over windows "
              f"{f('campaign_model_median_rhs_error_true_AU_active')} (active), energy-weighted "
              f"{f('campaign_model_energy_rhs_error_true_AU')}"
              + (f", on the measured (A, U) {f('campaign_model_median_rhs_rel_error_active')} (active)"
                 if v["campaign_model"]["rhs"] is not None else "") + f"; {curve_text}")
    print(f"wrote {len(written)} files to {args.out}")
    return 0


def register(sub) -> None:
    s = sub.add_parser("validate", help="score identification results against the truth of a synthetic campaign")
    s.add_argument("campaign", metavar="CAMPAIGN_DIR", help="directory of <event_id>.nc event files")
    s.add_argument("results", metavar="RESULTS_DIR", help="directory of <event_id>.identify.nc results")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--clusters", default=None, metavar="CSV", help="cluster_labels.csv of vivbench cluster (optional)")
    s.add_argument("--forecasts", default=None, metavar="DIR",
                   help="directory of forecast_<event_id>.csv of vivbench forecast (optional; stopped runs counted apart)")
    s.add_argument("--tau", type=float, default=0.2, help="regime threshold for the truth (docs/concepts.md (regimes))")
    s.add_argument("--active-share", type=float, default=0.1,
                   help="a window has dynamics when its true dA/dt RMS is at least this share of the event's (default 0.1)")
    s.set_defaults(func=run)
