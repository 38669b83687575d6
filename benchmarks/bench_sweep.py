"""Throughput of a recovery sweep (campaigns per minute) on 1 and 2 local worker processes.

Run: ``.venv/bin/python benchmarks/bench_sweep.py`` (or ``make bench``).
The sweep: 8 campaigns (2 accelerometer noise floors x 4 replicates, turbulence
intensity drawn per campaign) of 2 events of 10 min, each generated,
identified and scored. The wall time (best of two runs) includes starting the worker
processes, as a user sees it. The two tables must be byte-identical; the script checks
that and reports the scaling ratio (throughput with 2 workers / with 1), the
CPU time per campaign (all processes) and the load average before each run:
on a shared machine other work takes the second core and the ratio says so.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import resource  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

from _timing import best_of  # noqa: E402

from vivbench.validate import run_sweep, sweep_config_from_dict  # noqa: E402

SWEEP = {
    "seed": 0,
    "n_campaigns": 4,
    "n_events": 2,
    "duration": [600.0, 600.0],
    "grid": {"noise_density": [30.0, 300.0]},
    "ranges": {"turbulence_intensity": [0.04, 0.12]},
}


def _cpu_seconds() -> float:
    """CPU time of this process and of its finished children (the worker processes), s."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


REPEATS = 2  # best of two: the shared machine stalls now and then


def main() -> dict:
    config = sweep_config_from_dict(SWEEP)
    results: dict[str, float] = {"campaigns": config.n_tasks}
    tables = {}
    for workers in (1, 2):
        cpu = []

        def once(workers=workers):
            # A fresh directory each time: a finished sweep would only be read back.
            before = _cpu_seconds()
            with tempfile.TemporaryDirectory() as tmp:
                result = run_sweep(config, Path(tmp) / "sweep", workers=workers)
                table = result.table.read_bytes()
            cpu.append(_cpu_seconds() - before)  # worker processes are reaped by now
            return result, table

        load = os.getloadavg()[0]
        elapsed, (result, tables[workers]) = best_of(once, repeats=REPEATS)
        if result.failures:
            raise RuntimeError(f"sweep tasks failed: {result.failures}")
        rate = 60.0 * config.n_tasks / elapsed
        results[f"sweep_s_{workers}_workers"] = elapsed
        results[f"campaigns_per_min_{workers}_workers"] = rate
        results[f"cpu_s_per_campaign_{workers}_workers"] = min(cpu) / config.n_tasks
        results[f"load_average_before_{workers}_workers"] = load
        print(f"sweep of {config.n_tasks} campaigns ({config.n_events} x {config.duration[0] / 60:.0f} min events): "
              f"{elapsed:.1f} s with {workers} worker(s), {rate:.1f} campaigns/min, "
              f"{min(cpu) / config.n_tasks:.2f} CPU s per campaign (load average before: {load:.1f} on "
              f"{os.cpu_count()} CPUs)")
    if tables[1] != tables[2]:
        raise RuntimeError("the sweep table differs between 1 and 2 workers")
    results["scaling_ratio"] = results["campaigns_per_min_2_workers"] / results["campaigns_per_min_1_workers"]
    print(f"throughput 2 workers / 1 worker: {results['scaling_ratio']:.2f}x (identical tables)")
    return results


if __name__ == "__main__":
    main()
