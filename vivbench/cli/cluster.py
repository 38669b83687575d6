"""``vivbench cluster``: density-peaks clustering of a campaign's window models."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from vivbench.core.errors import InputError

_LABEL_COLUMNS = ("event_id", "window", "equation", "window_start", "window_end", "feature_set", "label", "halo")


def _write_csv(path: Path, rows: list[dict], columns) -> None:
    from vivbench.io.netcdf import atomic_path

    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(columns), lineterminator="\n")
            w.writeheader()
            w.writerows(rows)


def _fmt(x):
    return f"{x:.6g}" if isinstance(x, float) else x


def run(args) -> int:
    from vivbench.analysis.interpret import ClusterConfig, campaign_windows, cluster_windows
    from vivbench.analysis.clustering import decision_graph
    from vivbench.io.netcdf import atomic_path

    config = ClusterConfig(kernel=args.kernel, dc_fraction=args.dc_fraction, n_centers=args.centers)
    from vivbench.io.result import list_results

    files = list_results(args.results_dir)
    if args.campaign is not None and not Path(args.campaign).is_dir():
        raise InputError(f"{args.campaign}: not a campaign directory")
    windows = campaign_windows(files, args.campaign)
    results = cluster_windows(windows, config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    label_rows, summary_rows, summary = [], [], {"n_window_models": windows.n_points, "n_events": len(files),
                                                   "kernel": config.kernel, "dc_fraction": config.dc_fraction,
                                                   "truth_available": windows.has_truth}
    for name, res in results.items():
        m = res.model
        for i in range(windows.n_points):
            label_rows.append({"event_id": windows.event_id[i], "window": int(windows.window[i]),
                               "equation": windows.equation[i], "window_start": _fmt(float(windows.window_start[i])),
                               "window_end": _fmt(float(windows.window_end[i])), "feature_set": name,
                               "label": int(m.labels_[i]), "halo": int(m.halo_[i])})
        for row in res.summary:
            summary_rows.append({"feature_set": name, **{k: _fmt(v) for k, v in row.items()}})
        summary[f"n_clusters_{name}"] = res.n_clusters
        summary[f"ari_{name}"] = res.scores["ari"]
        summary[f"purity_{name}"] = res.scores["purity"]
        summary[f"dc_{name}"] = m.dc_
        with atomic_path(out / f"decision_graph_{name}.png", suffix=".png") as tmp:
            decision_graph(m.rho_, m.delta_, m.centers_, tmp)
    _write_csv(out / "cluster_labels.csv", label_rows, _LABEL_COLUMNS)
    columns = ["feature_set"] + list(results[next(iter(results))].summary[0].keys())
    _write_csv(out / "cluster_summary.csv", summary_rows, columns)
    with atomic_path(out / "summary.json") as tmp:
        # NaN (no truth) is written as null, which JSON readers accept
        clean = {k: (None if isinstance(v, float) and v != v else v) for k, v in summary.items()}
        tmp.write_text(json.dumps(clean, indent=1, sort_keys=True) + "\n")
    print(f"clustered {windows.n_points} window models of {len(files)} events into {out}: "
          + ", ".join(f"{n} {r.n_clusters} clusters" + (f" (ARI {r.scores['ari']:.3f})" if windows.has_truth else "")
                      for n, r in results.items()))
    return 0


def register(sub) -> None:
    s = sub.add_parser("cluster", help="density-peaks clustering of the window models of identification results")
    s.add_argument("results_dir", help="directory of <event_id>.identify.nc files")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--campaign", default=None, help="campaign directory with the event files (truth regimes)")
    s.add_argument("--kernel", default="cutoff", choices=("cutoff", "gaussian"), help="local density (default cutoff)")
    s.add_argument("--dc-fraction", type=float, default=0.02,
                   help="d_c as this quantile of the pairwise distances (default 0.02)")
    s.add_argument("--centers", type=int, default=None, help="number of clusters (default: automatic)")
    s.set_defaults(func=run)
