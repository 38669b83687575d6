"""Wall time of the default 31-event campaign (generation and writing), 1 and 2 workers.

Run: ``.venv/bin/python benchmarks/bench_campaign.py`` (or ``make bench``).
The target is at most 30 s on a 2-core machine; this script reports the
figure, it asserts nothing.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from vivbench.synth import CampaignConfig, generate_campaign  # noqa: E402


def main() -> dict:
    campaign = CampaignConfig()
    results = {}
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            res = generate_campaign(campaign, Path(tmp), workers=workers)
            elapsed = time.perf_counter() - t0
            size = sum(f.stat().st_size for f in res.files)
            hours = sum(float(line.split(",")[4]) for line in res.catalogue.read_text().splitlines()[1:]) / 3600
        results[f"campaign_s_{workers}_workers"] = elapsed
        print(f"default campaign ({campaign.n_events} events, {hours:.1f} h of data, {size / 1e6:.0f} MB): "
              f"{elapsed:.1f} s with {workers} worker(s)")
    results["scaling_ratio"] = results["campaign_s_1_workers"] / results["campaign_s_2_workers"]
    print(f"target <= 30 s on 2 cores; speed-up 1 -> 2 workers: {results['scaling_ratio']:.2f}x")
    return results


if __name__ == "__main__":
    main()
