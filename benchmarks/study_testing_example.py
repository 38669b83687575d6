"""The method of docs/testing.md outside the class where it recovers the truth exactly.

docs/testing.md tests a per-section least-squares fit over A_k^i U_k^j on one-section
bridges with polynomial aerodynamics, where the truth lies in its class. This script scores
the same method, through ``vivbench.testing.assert_recovers``'s own figures, on 10 events per
case (hypothesis's derandomized draws of ``vivbench.testing.events``, 4-6 min each) where it
does not: three sections (the truth's dA_k/dt depends on every section's wind), realistic
aerodynamics (not polynomials), or both. Per event: the median relative dA/dt error over
windows with dynamics and the share of windows with the true regime (docs/concepts.md (regimes)).

Run: ``.venv/bin/python benchmarks/study_testing_example.py``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402

DOC = Path(__file__).resolve().parents[1] / "docs" / "testing.md"
EXAMPLES = 10
_FIGURES = re.compile(r"median dA/dt error (\S+) .*regime accuracy (\S+) on")


def main(argv=None) -> dict:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    code = "\n".join(re.findall(r"^```python\n(.*?)^```", DOC.read_text(), flags=re.S | re.M))
    ns: dict = {}
    exec(compile(code, str(DOC), "exec"), ns)  # noqa: S102 - our own documentation
    vst, assert_recovers, method = ns["vst"], ns["assert_recovers"], ns["PolynomialLSQ"]
    cases = {
        "1 section, in_library": (1, "in_library"),
        "3 sections, in_library": (3, "in_library"),
        "1 section, realistic": (1, "realistic"),
        "3 sections, realistic": (3, "realistic"),
    }
    out = {}
    for name, (n_sections, kind) in cases.items():
        errors, accuracies = [], []
        generator = vst.generators(bridge=vst.bridges(n_sections=n_sections), aero=vst.aero_curves(kind=kind))

        @settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                  suppress_health_check=list(HealthCheck))
        @given(event=vst.events(generator=generator))
        def score(event):
            try:
                # Impossible tolerances: the AssertionError always carries the event's figures.
                assert_recovers(method(), event, rhs_tolerance=-1.0, regime_accuracy=1.01)
            except AssertionError as exc:
                m = _FIGURES.search(str(exc))
                errors.append(float(m.group(1)))
                accuracies.append(float(m.group(2)))

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            score()
        acc = np.array(accuracies)
        out[name] = {"events": len(errors), "rhs_error_median": float(np.median(errors)),
                     "rhs_error_max": float(np.max(errors)), "regime_accuracy_median": float(np.nanmedian(acc)),
                     "events_regime_accuracy_ge_0.9": int(np.sum(acc >= 0.9))}
        print(f"{name}: {json.dumps(out[name])}", flush=True)
    return out


if __name__ == "__main__":
    main()
