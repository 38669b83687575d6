"""
Plug in and score a method
==========================

Any object with ``fit(records)`` whose fitted model gives ``order_contributions(record)``
is a method. Here a plain least-squares fit of the amplitude equation is scored beside the
built-in campaign model on the same records, windows and truth, with the scores that
``vivbench compare`` and ``vivbench leaderboard`` report.
"""

# %%
# A small realistic campaign, identified: the records every method fits are the
# identification's envelopes A, winds U and derivatives dA/dt.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from vivbench.analysis import identify_files
from vivbench.io import list_events, list_results
from vivbench.synth import CampaignConfig, generate_campaign
from vivbench.validate import score_method, scoring_inputs

work = Path(tempfile.mkdtemp())
generate_campaign(CampaignConfig(n_events=6, seed=5, duration=(1500.0, 2100.0)), work / "campaign")
identify_files(list_events(work / "campaign"), work / "identify")
events, results = list_events(work / "campaign"), list_results(work / "identify")
records, truths, windows = scoring_inputs(events, results)
print(f"{len(records)} records, {records[0].A.shape[1]} sections")


# %%
# The method: dA_k/dt = sum_ij c_kij A_k^i U_k^j (i = 0..3, j = 0..2), least squares over all
# records. Its order contributions are the terms grouped by their power of A.
class PolynomialLSQ:
    """dA_k/dt as a polynomial in A_k and U_k, fitted by least squares to every record."""

    terms = [(i, j) for i in range(4) for j in range(3) if i or j]

    def fit(self, records):
        X = np.concatenate([self._features(r) for r in records])  # (n, S, p)
        y = np.concatenate([r.dA for r in records])  # (n, S), m/s
        self.coef_ = np.empty((X.shape[1], len(self.terms)))
        for k in range(X.shape[1]):
            ok = np.isfinite(X[:, k]).all(axis=1) & np.isfinite(y[:, k])
            self.coef_[k] = np.linalg.lstsq(X[ok, k], y[ok, k], rcond=None)[0]
        return self

    def order_contributions(self, record):
        terms = self._features(record) * self.coef_  # (n, S, p), m/s
        power = np.array([i for i, _ in self.terms])
        return np.stack([terms[..., power == i].sum(axis=-1) for i in range(4)], axis=-1)

    def _features(self, record):
        a, u = record.A / 0.05, record.U / 8.0  # columns of order one
        return np.stack([a**i * u**j for i, j in self.terms], axis=-1)


# %%
# Score both on the identification's own windows. ``"varying"`` is the built-in campaign
# model (``VaryingCoefficientSINDy`` with its verdict); a factory path such as
# ``"my_methods:make"`` works the same way.
scores = {
    "PolynomialLSQ": score_method(PolynomialLSQ(), records, truths, windows=windows, simulate=False),
    "varying": score_method("varying", records, truths, windows=windows, simulate=False),
}
columns = {"coverage": "coverage", "accuracy_identifiable": "acc. flagged", "accuracy_all": "acc. all",
           "rhs_error_true_AU_median_active": "dA/dt err. median", "rhs_error_true_AU_energy": "dA/dt err. energy"}
print(f"{'method':<14}" + "".join(f"{c:>19}" for c in columns.values()))
for name, s in scores.items():
    print(f"{name:<14}" + "".join(f"{s[k]:>19.3f}" for k in columns))
print(f"chance level (most common true regime): {scores['varying']['truth_majority_share']:.3f}")

# %%
# The least-squares fit has no verdict (coverage 0): it is scored on every window. Its dA/dt
# may be close, yet its regimes, read from how it splits dA/dt between the powers of A,
# are another matter.
fig, ax = plt.subplots(figsize=(6, 3.2))
labels = ["accuracy, all windows", "dA/dt error (median)", "dA/dt error (energy)"]
for n, (name, s) in enumerate(scores.items()):
    vals = [s["accuracy_all"], s["rhs_error_true_AU_median_active"], s["rhs_error_true_AU_energy"]]
    ax.bar(np.arange(3) + 0.38 * n, vals, width=0.38, label=name)
ax.set_xticks(np.arange(3) + 0.19, labels)
ax.set_ylabel("score (-)")
ax.legend()
fig.tight_layout()
