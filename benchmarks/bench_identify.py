"""The identification chain on synthetic campaigns: speed and recovery of the truth.

Run: ``.venv/bin/python benchmarks/bench_identify.py [n_events]`` (default 31).

1. Speed: the whole chain (read, preprocess, TV derivative, windowed SINDy
   with AICc and the identifiability competitors, write) over the default
   campaign with 1 and 2 workers; and the regressions alone against the loop a
   user would write with pysindy (``benchmarks/bench_sindy.py`` on the
   campaign's own windows and threshold path).
2. Recovery (docs/concepts.md (regimes), issue 3): regime accuracy on identifiable windows,
   coverage, accuracy on the rest, and the median relative RMS error of the
   identified dA/dt against the true averaged dynamics, on a noise-free,
   defect-free campaign with slowly varying wind and on the default (realistic)
   campaign; for the window models (the paper's method) and for the campaign
   model of ``vivbench pool`` on the same windows.

Nothing is asserted; the figures are printed and returned.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import importlib.util  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402


from vivbench.models.campaign import PooledSINDy
from vivbench.analysis.identify import identify_files
from vivbench.analysis.pool import pool_results
from vivbench.io.campaign_model import write_campaign_regimes
from vivbench.synth import CampaignConfig, GeneratorConfig, generate_campaign  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/_campaigns.py
from _campaigns import CLEAN  # noqa: E402
from vivbench.validate import campaign_recovery, campaign_model_recovery  # noqa: E402



def main(n_events: int = 31) -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, gen in (("clean", CLEAN), ("default", GeneratorConfig())):
            camp = generate_campaign(CampaignConfig(n_events=n_events, generator=gen), tmp / name / "events", workers=2)
            timings = {}
            for workers in ((1, 2) if name == "default" else (2,)):
                t0 = time.perf_counter()
                results, failures = identify_files(camp.files, tmp / name / f"results{workers}", workers=workers)
                timings[f"chain_s_{workers}_workers"] = time.perf_counter() - t0
                if failures:
                    print("failures:", failures)
            rec = campaign_recovery(camp.files, results)
            out[name] = {**timings, **rec}
            print(f"\n[{name} campaign, {n_events} events]")
            for k, v in timings.items():
                print(f"  whole chain: {v:.1f} s ({k})")
            print(f"  windows x equations scored: {rec['n']}; true regime shares: "
                  + ", ".join(f"{k}: {v:.2f}" for k, v in rec["truth_regime_shares"].items()))
            print(f"  coverage (identifiable): {rec['coverage']:.3f}")
            print(f"  regime accuracy, identifiable windows: {rec['accuracy_identifiable']:.3f}")
            print(f"  regime accuracy, not identifiable:     {rec['accuracy_not_identifiable']:.3f}")
            print(f"  regime accuracy, all windows:          {rec['accuracy_all']:.3f}")
            print(f"  median relative RMS error of dA/dt, all windows: {rec['rhs_median_rel_error']:.4f}")
            print(f"  same, windows with true |dA/dt| >= 10 % of the event RMS ({rec['active_share']:.2f} of them): "
                  f"{rec['rhs_median_rel_error_active']:.4f}")
            # The campaign model (vivbench pool) on the same windows.
            t0 = time.perf_counter()
            pooled = write_campaign_regimes(pool_results(results, PooledSINDy()), tmp / name / "results2")
            t_pool = time.perf_counter() - t0
            prec = campaign_model_recovery(camp.files, pooled, results)
            out[name]["pooled"] = {"time_s": t_pool, **prec}
            print(f"  campaign model (vivbench pool, {t_pool:.1f} s): coverage {prec['coverage']:.3f}; regime accuracy "
                  f"{prec['accuracy_identifiable']:.3f} identifiable, {prec['accuracy_not_identifiable']:.3f} not, "
                  f"{prec['accuracy_all']:.3f} all; median dA/dt error {prec['rhs_median_rel_error']:.4f} all, "
                  f"{prec['rhs_median_rel_error_active']:.4f} active windows")

        # The regressions alone against the pysindy loop, on the default campaign's own windows.
        spec = importlib.util.spec_from_file_location("bench_sindy", Path(__file__).with_name("bench_sindy.py"))
        bench_sindy = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(bench_sindy)
        ev_arrays = bench_sindy.events_from_results(tmp / "default" / "results2")
    print("\n[regressions only, default campaign windows, vs pysindy]")
    out["engine_vs_pysindy"] = bench_sindy.main(events=ev_arrays)
    return out


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 31)
