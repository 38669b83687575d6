"""Whole-event simulation NMSE of a campaign model of ``vivbench pool`` over every event of its results.

Run::

    .venv/bin/python benchmarks/study_campaign_simulation.py RESULTS_DIR [RESULTS_DIR ...]

For each directory (results with ``campaign.model.nc`` beside them, as
``vivbench pool`` leaves them), every event is simulated as ``vivbench
forecast`` does for its ``campaign_model_simulation`` row: the model from
``vivbench.analysis.load_campaign_model``, the measured record through
``vivbench.models.measured_input`` (the wind as at fit), from the measured A
at the first window's start to the last window's end. Printed, one JSON line
per directory: the median and 90th percentile over events of the NMSE at the
reference section, and how many runs were stopped (left the plausible range).
Nothing is asserted. ``vivbench forecast`` gives the same number for one event.
"""

from __future__ import annotations

import argparse
import json
import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from vivbench.analysis import load_campaign_model, campaign_wind_smoothing  # noqa: E402
from vivbench.core.terms import reference_section  # noqa: E402
from vivbench.io.campaign_model import read_campaign_regimes, regimes_file  # noqa: E402
from vivbench.io.result import list_results, read_result, result_record  # noqa: E402
from vivbench.models import measured_input  # noqa: E402


def simulation_scores(results_dir) -> dict:
    """Median and 90th percentile over events of the whole-event NMSE at the reference section."""
    from pathlib import Path

    results_dir = Path(results_dir)
    model = load_campaign_model(results_dir)
    pooled = regimes_file(results_dir)
    smoothing = campaign_wind_smoothing(read_campaign_regimes(pooled) if pooled.is_file() else None)
    nmse, stopped = [], 0
    for path in list_results(results_dir):
        res = read_result(path)
        record = measured_input(model, result_record(res), wind_smoothing_s=smoothing)
        span = (float(res["window_start"].values.min()), float(res["window_end"].values.max()))
        sim = model.simulate(record, *span)
        nmse.append(float(sim.nmse[reference_section(record.n_sections)]))
        stopped += int(bool(sim.stopped))
    return {"results": str(results_dir), "model": type(model).__name__, "n_events": len(nmse),
            "median_nmse": float(np.median(nmse)), "p90_nmse": float(np.percentile(nmse, 90)), "stopped": stopped}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", help="results directories pooled by vivbench pool")
    rows = []
    for directory in parser.parse_args(argv).results:
        rows.append(simulation_scores(directory))
        print(json.dumps(rows[-1]), flush=True)
    return {"directories": rows}


if __name__ == "__main__":
    main()
