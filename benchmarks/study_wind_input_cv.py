"""What the data say about the varying model's wind input: held-out prediction of the measured dA/dt.

Run: ``.venv/bin/python benchmarks/study_wind_input_cv.py RESULTS_DIR``
(``RESULTS_DIR``: the ``<event_id>.identify.nc`` of a campaign).

Fits ``VaryingCoefficientSINDy`` twice on the same records as ``vivbench pool``
(the campaign derivative of dA/dt): with the mean wind (the default) and with
every section's wind (``wind_input="additive"`` with ``SEED0_ADDITIVE_SETTINGS``, the
settings ``vivbench pool --wind-input additive`` had before it chose them as for the others), and prints per equation the
leave-one-event-out squared prediction error of each event's measured dA/dt
(``subset_loeo_event_`` of the model with every order): its median over the
events and its sum. No truth is read: this is what a user can score. The
truth's side (dA/dt error on the true (A, U)) is in
``benchmarks/study_misspecification.py`` and ``vivbench validate``. It asserts
nothing.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.analysis.pool import CAMPAIGN_DERIVATIVE, records_from_results  # noqa: E402
from vivbench.io.result import list_results  # noqa: E402
from varying_settings import SEED0_ADDITIVE_SETTINGS  # noqa: E402
from vivbench.models.varying import VaryingCoefficientSINDy  # noqa: E402


def _fmt(x: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.3e}" for v in x) + "]"


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("results", help="directory of <event_id>.identify.nc")
    args = p.parse_args(argv)
    records = records_from_results(list_results(Path(args.results)), derivative=CAMPAIGN_DERIVATIVE)
    print(f"{len(records)} events of {args.results}; leave-one-event-out squared error of the measured dA/dt, "
          "m^2/s^2, per equation")
    out = {}
    for name, params in (("mean", {}), ("additive", {"wind_input": "additive", **SEED0_ADDITIVE_SETTINGS})):
        model = VaryingCoefficientSINDy(n_bootstrap=0, **params).fit(records)
        loss = model.subset_loeo_event_[0]  # (S, E): the subset with every order
        out[name] = {"median": np.nanmedian(loss, axis=1).tolist(), "sum": np.nansum(loss, axis=1).tolist()}
        print(f"{name:9s} median over events {_fmt(np.nanmedian(loss, axis=1))}, sum {_fmt(np.nansum(loss, axis=1))}")
    out["ratio"] = float(np.sum(out["additive"]["sum"]) / np.sum(out["mean"]["sum"]))
    print(f"additive / mean, summed over equations and events: {out['ratio']:.2f}")
    return out


if __name__ == "__main__":
    main()
