"""A selection's candidates adapted to the records: the settings the simplest candidate settles hold for all."""

from __future__ import annotations

import numpy as np

from tests.helpers import bell_records
from vivbench.analysis.candidates import settle_candidates
from vivbench.analysis.selection import Candidate, varying_selection
from vivbench.models import QuasiSteadyAmplitude, VaryingCoefficientSINDy


class _Settles:
    """A stand-in model that settles ``wind_smoothing_s`` to 12 s on any records."""

    def __init__(self, wind_smoothing_s: float = 30.0):
        self.wind_smoothing_s = wind_smoothing_s

    def get_params(self) -> dict:
        return {"wind_smoothing_s": self.wind_smoothing_s}

    def settle(self, records):
        return {"wind_smoothing_s": 12.0, "wind_smoothing_grid": None}, {"wind_smoothing": {"chosen_s": 12.0}}

    def fit(self, records):
        return self


def test_the_simplest_candidates_settlement_is_given_to_every_model_that_has_the_parameters():
    cands = [Candidate(name="rich", model=VaryingCoefficientSINDy(wind_smoothing_grid=(10.0, 30.0)), complexity=1),
             Candidate(name="simple", model=_Settles(), complexity=0)]
    settled, null, evidence = settle_candidates(cands, QuasiSteadyAmplitude(), records=[])
    assert evidence == {"wind_smoothing": {"chosen_s": 12.0}}
    assert settled[0].model.get_params()["wind_smoothing_s"] == 12.0
    assert settled[0].model.get_params()["wind_smoothing_grid"] is None
    assert settled[1].model.wind_smoothing_s == 12.0 and null.wind_smoothing_s == 12.0
    assert cands[0].model.wind_smoothing_grid == (10.0, 30.0)  # the given models are not changed
    # A simplest candidate that settles nothing leaves every model as given.
    plain = [Candidate(name="a", model=VaryingCoefficientSINDy(), complexity=0)]
    same, none, ev = settle_candidates(plain, None, records=[])
    assert same[0].model is plain[0].model and none is None and ev == {}


def test_a_selection_chooses_the_smoothing_once_and_keeps_its_parameters():
    records = bell_records(8, seed=0, duration_s=1200.0, dt_s=0.5, mode_shape=np.linspace(1.0, 0.6, 2),
                           wind_period_s=(600.0, 100.0), amplitude_period_s=300.0)
    sel = varying_selection(criterion="derivative", options={"yaw_degree": (0,), "penalty_choice": ("cv", "least")},
                            n_perturbations=1, n_basis=(11,), n_bootstrap=0, wind_smoothing_grid=(0.0, 30.0))
    sel.fit(records)
    ev = sel.evidence()["wind_smoothing"]
    # The deck's own wind: smoothing only blurs it, so the 30 s prior is beaten and 0 s holds for every model.
    assert ev["candidates_s"] == [0.0, 30.0] and ev["prior_s"] == 30.0 and ev["chosen_s"] == 0.0
    fitted = [sel.model_, *sel.set_models_, *sel.perturbed_models_]
    assert {m.fitted_wind_smoothing() for m in fitted} == {0.0}
    assert "wind smoothing 0 s for every model" in sel.evidence_text()
    varying = [c for c in sel.candidates if c.options["model_class"] == "varying"]
    assert {c.model.wind_smoothing_grid for c in varying} == {(0.0, 30.0)}  # the parameters as given
    assert {c.model.wind_smoothing_s for c in sel.candidates} == {30.0}
    assert sel.null_model.wind_smoothing_s == 30.0
