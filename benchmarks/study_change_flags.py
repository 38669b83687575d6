"""Per-event "not predicted" flags of the varying campaign model on whole campaigns (issue 11).

For each case (a campaign's results, optionally the first event of a known
change) the varying model is fitted as ``vivbench pool --model varying`` fits
it (without the bootstrap, which the flags do not use), and the script prints
the model change scan (p, located event), the flags of
:mod:`vivbench.analysis.changes` (``event_after_change`` when the scan
detects, :func:`change_relative_flags` at the scan's best split whether or not
it detects, :func:`offset_flags`, the held-out misfit flags) and, with a
known change, the events flagged before and after it. Run (``DRIFT``: a campaign
with a change at its 10th event, e.g. of ``examples/drift.toml``, and its results)::

    python benchmarks/run_study.py change_flags --case drift:DRIFT/identify:10 --case demo:demo/identify
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.analysis import CAMPAIGN_DERIVATIVE, records_from_results  # noqa: E402
from vivbench.analysis.changes import (change_relative_flags, event_residual_checks, offset_flags,  # noqa: E402
                                       offset_strata, statistics_change_scan)
from vivbench.models import VaryingCoefficientSINDy  # noqa: E402


def run_case(results: Path, change: int | None) -> dict:
    """The scan and the flags of one campaign's results (``change``: first event number after a known change)."""
    t0 = time.perf_counter()
    recs = records_from_results(sorted(results.glob("*.identify.nc")), derivative=CAMPAIGN_DERIVATIVE)
    model = VaryingCoefficientSINDy(n_bootstrap=0).fit(recs)
    recs = [model.measured_wind(r) for r in recs]
    ids = np.array([r.event_id for r in recs])
    checks = event_residual_checks(model, recs)
    stats = model.event_statistics(recs)
    t1 = time.perf_counter()
    scan = statistics_change_scan(stats, seed=model.seed)
    t2 = time.perf_counter()
    k = scan["change_index"]
    rel = change_relative_flags(stats, k, checks["linear_offset_se"], model.a_ref_, model.y_scale_,
                                n_pieces=checks["n_pieces"])
    off = offset_flags(checks["linear_offset"], checks["linear_offset_se"], n_pieces=checks["n_pieces"],
                       stratum=offset_strata(checks["residual_rel_rms"]))
    after = np.arange(ids.size) >= k if scan["detected"] else np.zeros(ids.size, dtype=bool)

    post = (np.array([int(e[1:]) >= change for e in ids]) if change is not None
            else np.zeros(ids.size, dtype=bool))

    def show(flag) -> dict:
        flag = np.asarray(flag, dtype=bool)
        return {"events": ",".join(ids[flag]) or "-", "after_change": int((flag & post).sum()),
                "before_change_or_false": int((flag & ~post).sum())}

    return {"n_events": int(ids.size), "known_change_event": change, "n_after_change": int(post.sum()),
            "scan_p": float(scan["p_value"]), "scan_event": str(ids[k]) if k >= 0 else "-",
            "scan_detected": bool(scan["detected"]), "fit_s": t1 - t0, "scan_s": t2 - t1,
            "after_change_flags": show(after), "per_event_flags": show(rel["flag"]),
            "offset_flags": show(off["flag"]), "misfit_flags": show(scan["misfit_flag"])}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", action="append", required=True, help="NAME:RESULTS[:FIRST_CHANGED_EVENT_NUMBER]")
    args = parser.parse_args(argv)
    out = {}
    for case in args.case:
        parts = case.split(":")
        if len(parts) not in (2, 3):
            parser.error(f"--case {case!r}: give NAME:RESULTS[:FIRST_CHANGED_EVENT_NUMBER]")
        out[parts[0]] = run_case(Path(parts[1]), int(parts[2]) if len(parts) == 3 else None)
        print(parts[0], out[parts[0]], flush=True)
    return out


if __name__ == "__main__":
    main()
