"""The grey-box refit as a method of the protocol (docs/methods.md), given the bridge's structural properties.

:class:`GreyBoxMethod` fits :class:`vivbench.models.GreyBoxRefit` to a campaign's records as
``vivbench greybox`` does after ``vivbench pool``: the measured wind (and yaw) smoothed by
``wind_smoothing_s``, the default campaign model (the varying-coefficient model chosen by
held-out events, :class:`vivbench.validate.CampaignMethod` ``"varying"``) fitted to the same
records for the grey-box's warm start (its curves) and as the verdict's reference (a window is
flagged only where both give the same regime, :func:`vivbench.regimes.greybox_window_verdicts`).
The fitted :class:`GreyBoxVerdictModel` is scored by :func:`vivbench.validate.score_fitted`
like every other method: its ``predict``, ``order_contributions`` and ``curves`` take a
record's wind as given (the truth's felt wind for the dA/dt error on the true (A, U)); its
verdict, window regimes and simulations see a measured record's wind as it was at fit.

The grey-box needs the bridge's properties, which a field user takes from design documents
and tests (:class:`vivbench.models.BridgeProperties`). On a synthetic campaign
:func:`structural_properties` reads them from the generator's structure alone: modal mass per
length, deck depth, frequency, structural damping ratio, air density, mode shape and
tributary lengths. Nothing of the aerodynamics (Y1, e1, e2, C_L, the Strouhal number, the yaw
effect, the buffeting) reaches the fit. On a draw with a damping step the ratio given is the
one before the step (the design value).

Options of the grey-box that were fixed on the default campaign A and are kept as they are
here: the 30 s Gaussian wind smoothing (``wind_smoothing_s``), the penalty grid (0.1, 0.3, 1)
scored by GCV, 16 B-splines per function, the verdict's 95 % agreement over 100 parameter
draws and the ``sandwich_bias_wind`` band (:class:`vivbench.models.GreyBoxRefit`).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Sequence

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU
from vivbench.models.greybox import BridgeProperties, GreyBoxRefit
from vivbench.models.model_input import measured_input
from vivbench.models.protocol import chosen_model, model_evidence
from vivbench.preprocess.wind_smoothing import smooth_wind
from vivbench.regimes.greybox import greybox_window_verdicts
from vivbench.synth.config import StructureConfig
from vivbench.validate.methods import CampaignMethod, MeasuredWindVerdictModel

__all__ = ["STRUCTURAL_FIELDS", "GreyBoxMethod", "GreyBoxVerdictModel", "structural_properties"]

#: The bridge properties an engineer knows and the grey-box is given (all structural).
STRUCTURAL_FIELDS = ("mass", "depth", "frequency", "damping_ratio", "air_density", "mode_shape", "tributary_lengths")


def structural_properties(structure: StructureConfig) -> BridgeProperties:
    """The bridge properties of a generated bridge that a field engineer would have.

    Parameters
    ----------
    structure : vivbench.synth.StructureConfig
        The generator's structure (``GeneratorConfig.structure``); never its aerodynamics.

    Returns
    -------
    BridgeProperties
        :data:`STRUCTURAL_FIELDS` of ``structure``: mass (kg/m), deck depth (m), frequency
        (Hz), structural damping ratio, air density (kg/m^3), mode shape and tributary
        lengths (m).

    Raises
    ------
    InputError
        ``structure`` is not a StructureConfig (a whole generator configuration, which holds
        the aerodynamic truth, is refused).
    """
    if not isinstance(structure, StructureConfig):
        raise InputError(f"structural_properties takes the generator's StructureConfig (its structure alone); "
                         f"got {type(structure).__name__}")
    return BridgeProperties(**{name: getattr(structure, name) for name in STRUCTURAL_FIELDS})


def _greybox_verdict(model: GreyBoxRefit, record: Record, window_start, window_end, *, reference,
                     wind_smoothing_s: float, tau: float, agreement: float, n_draws: int,
                     dynamics_shown: bool = True) -> dict:
    """:func:`greybox_window_verdicts` of a measured record: its wind smoothed as at fit, the reference's
    record as the reference saw it at its own fit; no window flagged when the campaign's held-out
    evidence does not show its dynamics."""
    ref_rec = None if reference is None else measured_input(reference, record)
    out = greybox_window_verdicts(model, smooth_wind(record, wind_smoothing_s), window_start, window_end, tau=tau,
                                  agreement=agreement, n_draws=n_draws, reference=reference, reference_record=ref_rec)
    if not dynamics_shown:
        out = {**out, "identifiable": np.zeros(np.shape(out["identifiable"]), dtype=bool)}
    return out


class GreyBoxVerdictModel(MeasuredWindVerdictModel):
    """A fitted grey-box model with the verdict of ``vivbench greybox`` on measured records.

    ``identifiable`` (the verdict and the noise floor) and ``window_regimes`` see a measured
    record's wind smoothed as at fit (:func:`greybox_window_verdicts`, with the reference);
    every other attribute (``predict``, ``order_contributions``, ``curves``,
    ``physical_curves``, ...) is the wrapped :class:`GreyBoxRefit`'s, on a record as given.

    Parameters
    ----------
    model : GreyBoxRefit, fitted on records smoothed by ``wind_smoothing_s``
    reference : fitted campaign model or None (the verdict's reference; None: the draws alone)
    wind_smoothing_s : float, s
    tau, agreement, n_draws : the verdict's settings (:func:`greybox_window_verdicts`)
    reference_seconds : wall time of the reference's fit, s (NaN: given fitted)
    evidence : dict or None
        The reference's held-out evidence (:meth:`vivbench.analysis.ModelSelection.evidence`), returned by
        :meth:`evidence`; when it does not show the campaign's dynamics (``dynamics_shown`` False, the
        null test) or its chosen model's change scan locates a change (``stationary`` False), no window
        is flagged.
    """

    def __init__(self, model: GreyBoxRefit, reference=None, *, wind_smoothing_s: float = 30.0,
                 tau: float = DEFAULT_TAU, agreement: float = 0.95, n_draws: int = 100,
                 reference_seconds: float = math.nan, evidence: dict | None = None):
        shown = True if evidence is None else bool(evidence.get("dynamics_shown", True)
                                                   and evidence.get("stationary", True))
        super().__init__(model, functools.partial(_greybox_verdict, reference=reference,
                                                  wind_smoothing_s=wind_smoothing_s, tau=tau, agreement=agreement,
                                                  n_draws=n_draws, dynamics_shown=shown))
        self._evidence = evidence
        self.reference = reference
        self.wind_smoothing_s = wind_smoothing_s
        self.reference_seconds = reference_seconds

    def evidence(self) -> dict | None:
        """The reference's held-out evidence the verdict rests on (None without a reference that has one)."""
        return self._evidence

    def simulate(self, record: Record, *args, **kwargs):
        """The grey-box ``simulate`` on the measured record's wind smoothed as at fit."""
        return self.model.simulate(smooth_wind(record, self.wind_smoothing_s), *args, **kwargs)


class GreyBoxMethod:
    """The grey-box refit as a method: ``fit(records)`` -> :class:`GreyBoxVerdictModel`.

    Parameters
    ----------
    bridge : BridgeProperties
        The bridge's structural properties (:func:`structural_properties` on a synthetic bridge).
    reference : "varying", None or a fitted campaign model
        "varying": the default campaign model (``CampaignMethod("varying")``) is fitted to the
        same records first; a fitted model (e.g. that method's result) is used as it is; None:
        no warm start from a campaign model and a verdict from the parameter draws alone.
    wind_smoothing_s : float, s
        Gaussian smoothing of the measured wind and yaw (the default 30 s of ``vivbench
        greybox``, chosen on the default campaign A).
    tau, agreement, n_draws : the verdict's settings
    **params : :class:`GreyBoxRefit` parameters (its defaults otherwise; ``bridge`` and
        ``warm_start`` are set here)
    """

    def __init__(self, bridge: BridgeProperties, *, reference="varying", wind_smoothing_s: float = 30.0,
                 tau: float = DEFAULT_TAU, agreement: float = 0.95, n_draws: int = 100, **params):
        if not isinstance(bridge, BridgeProperties):
            raise InputError(f"GreyBoxMethod needs the bridge's BridgeProperties; got {type(bridge).__name__}")
        if isinstance(reference, str) and reference != "varying":
            raise InputError(f"reference must be 'varying', None or a fitted campaign model; got {reference!r}")
        if not (isinstance(wind_smoothing_s, (int, float)) and math.isfinite(wind_smoothing_s)
                and wind_smoothing_s >= 0):
            raise InputError(f"wind_smoothing_s must be a number of seconds >= 0; got {wind_smoothing_s!r}")
        unknown = {"bridge", "warm_start"} & set(params)
        if unknown:
            raise InputError(f"GreyBoxMethod sets {sorted(unknown)} itself; give the bridge as its first argument")
        self.bridge = bridge
        self.reference = reference
        self.wind_smoothing_s = float(wind_smoothing_s)
        self.tau, self.agreement, self.n_draws = tau, agreement, n_draws
        self.params = params

    def __repr__(self) -> str:
        ref = self.reference if self.reference is None or isinstance(self.reference, str) else "fitted"
        return f"GreyBoxMethod(reference={ref!r}, wind_smoothing_s={self.wind_smoothing_s:g})"

    def fit(self, records: Sequence[Record]) -> GreyBoxVerdictModel:
        """Fit the reference (when asked), then the grey-box on the smoothed records from its curves."""
        from vivbench.analysis.pool import curve_wind_grid

        records = list(records)
        if not records:
            raise InputError("no records to fit the grey-box model on")
        seconds = math.nan
        reference = self.reference
        if reference == "varying":
            t0 = time.perf_counter()
            reference = CampaignMethod("varying").fit(records)
            seconds = time.perf_counter() - t0
        evidence = None if reference is None else model_evidence(reference)
        reference = None if reference is None else chosen_model(reference)
        smoothed = [smooth_wind(r, self.wind_smoothing_s) for r in records]
        warm = None
        if reference is not None:
            wind = curve_wind_grid(np.concatenate([r.U.ravel() for r in smoothed]))
            try:
                warm = reference.curves(wind)
            except (InputError, AttributeError, ValueError):  # a reference without curves: equation-error start
                warm = None
        model = GreyBoxRefit(**self.params)
        model.set_params(bridge=self.bridge, warm_start=warm)
        model.fit(smoothed)
        return GreyBoxVerdictModel(model, reference, wind_smoothing_s=self.wind_smoothing_s, tau=self.tau,
                                   agreement=self.agreement, n_draws=self.n_draws, reference_seconds=seconds,
                                   evidence=evidence)
