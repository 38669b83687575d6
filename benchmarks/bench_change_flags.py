"""Per-event "not predicted" flags of the varying campaign model on whole campaigns (issue 11).

For each case (a campaign's results, optionally the first event of a known
change) the varying model is fitted as ``vivbench pool --model varying`` fits
it (without the bootstrap, which the flags do not use), and the script prints
the model change scan (p, located event), the flags of
:mod:`vivbench.analysis.changes` (``event_after_change`` when the scan
detects, :func:`change_relative_flags` at the scan's best split whether or not
it detects, :func:`offset_flags`, the held-out misfit flags) and, with a
known change, the events flagged before and after it. Run:

    python benchmarks/bench_change_flags.py --case drift:/tmp/vdrift-drift-id:10 --case nodrift:/tmp/vdrift-nodrift-id

Measured (2026-11-23, 99 orderings; drift = examples/drift.toml with the
retrofit at E010, 20 events; step = a damping step x2 from E007, 14 events,
seed 3; A, S1, B = the 31-event realistic campaigns):

case     E  scan p (event)  after-change  per-event (at best split)  offset flags  misfit flags
drift   20  0.02 (E010)     11/11, 0 pre  0/11                       1 (E020 post) 1 (E008 pre)
step    14  0.01 (E007)      8/8,  0 pre  0/8                        0             0
nodrift 20  0.01 (E007)     14 false      2/14 false                 0             0
A       31  0.94 (E028)      0            (0/4, not detected)        0             0
S1      31  0.89 (E007)      0            (0/25, not detected)       0             0
B       31  0.68 (E024)      0            (2/8, not detected)        4 false       0

(The offset flags above are the former rule's; with the stratified posterior
rule of :func:`offset_flags` see the docstring of :mod:`vivbench.analysis.changes`.)
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


def run_case(results: Path, change: int | None) -> str:
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

    def show(flag):
        flagged = ",".join(ids[flag]) or "-"
        if change is None:
            return f"{flagged} ({int(flag.sum())} false)"
        post = np.array([int(e[1:]) >= change for e in ids])
        return f"{flagged} ({int((flag & post).sum())}/{int(post.sum())} after, {int((flag & ~post).sum())} before)"

    return (f"  scan p = {scan['p_value']:.2f} at {ids[k] if k >= 0 else '-'} (scan {t2 - t1:.1f} s, fit {t1 - t0:.1f} s)\n"
            f"  after change:  {show(after)}\n  per event:     {show(rel['flag'])}  z = "
            f"{' '.join(f'{z:+.1f}' for z in rel['z'][k:]) if k >= 0 else '-'}\n"
            f"  offset flags:  {show(off['flag'])}\n  misfit flags:  {show(scan['misfit_flag'])}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", action="append", required=True, help="NAME:RESULTS[:FIRST_CHANGED_EVENT_NUMBER]")
    args = parser.parse_args(argv)
    for case in args.case:
        parts = case.split(":")
        if len(parts) not in (2, 3):
            parser.error(f"--case {case!r}: give NAME:RESULTS[:FIRST_CHANGED_EVENT_NUMBER]")
        print(parts[0], flush=True)
        print(run_case(Path(parts[1]), int(parts[2]) if len(parts) == 3 else None), flush=True)


if __name__ == "__main__":
    main()
