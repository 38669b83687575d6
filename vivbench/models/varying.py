"""A varying-coefficient campaign model: dA_k/dt = sum_i a_ki(U_k) A_k^i with spline curves a_ki(U).

The aerodynamic functions of the reduced velocity need not be polynomials (a
lock-in bell, docs/concepts.md (no inverse crime)). This model keeps the
physical structure of docs/concepts.md (the truth), dynamics cubic in A whose
coefficients are functions of the wind, and gives the coefficient functions a
flexible, smooth basis:

    a_ki(U) = sum_m c_kim B_m(U),   i = 0..3, m = 0..M-1,

with B_m a cubic B-spline basis (:mod:`vivbench.library.splines`) on M - 3
uniform intervals spanning the campaign's range of U_k (outside it the curves
are held constant). The coefficients are fitted by penalised least squares
(P-splines, Eilers & Marx 1996; :mod:`vivbench.regression.penalised`): the
residual sum of squares of the standardised target plus
lambda sum_i ||D2 c_ki||^2, D2 the second-difference matrix, so lambda -> inf
leaves straight lines in U and lambda -> 0 the unpenalised spline fit.

Criterion: M (from ``n_basis``) and lambda (from ``penalties``, relative to
trace(X^T X) / trace(P)) are chosen per section by K-fold cross-validation over
events (whole events are left out, so the correlation of derivative errors
within an event cannot make a rough fit look good); with
``penalty_choice="least"`` the fit then takes the least lambda that the final
fit's leave-one-event-out errors cannot tell from the best. Optionally
(``select_orders``) the same cross-validation drops every order whose removal
does not increase the cross-validated error.

Everything is computed from per-block sufficient statistics (X_b^T X_b, X_b^T y_b,
y_b^T y_b; :mod:`vivbench.models.varying_design`): the folds, the penalty grid
and the block bootstrap of the bands are small p x p solves (p = 4 M without
yaw), with no loop over samples.

Only own-section amplitudes are used: in the averaged truth the mode shape makes
the other sections' amplitudes proportional to A_k, so their terms are
collinear with A_k's.

The wind of the curves (``wind_input``): the truth sums the aerodynamic forces of every section j, each a
function of that section's own felt wind U_j and yaw psi_j, so with a wind that differs along the span dA_k/dt =
sum_i sum_j a_kij(U_j, psi_j) A_k^i, which no curve of one wind (the weighted mean over the sections,
``"mean"``, or the section's own, ``"section"``) represents when the curves are not linear. ``"additive"`` fits
that sum: every column repeated for each section's wind and yaw (p = 4 M (J + 1) S, the same penalty on every
section's curve; only the sum is identifiable, the penalty keeps the split smooth). The coefficient curve at
wind U is then the model at the uniform wind U_j = U, the sum over the sections. ``"sum"`` ties those curves to
one shape weighted by the sections' weights, a_kij = w_j f_ki (the same deck cross-section at every section, the
truth's form with modal weights): p = 4 M (J + 1) as with the mean wind, fitted from the additive statistics
tied by the weights (:func:`vivbench.models.varying_stats.tied_statistics`).

With the wind's yaw (``yaw_degree`` > 0; by default whenever the records carry it) its yaw psi (its angle to the
span's normal, which U does not carry) is a second covariate: every column above is repeated times sin^2j(psi),
j = 1..J, with the same penalty (p = 4 M (J + 1)); beyond the fitted range of sin^2(psi) it is held at its ends,
as U is. After the fit the same statistics give the models of every subset of the orders 0, 2, 3 (order 1 always
kept) and their leave-one-event-out prediction errors: the confidence set of ``model_set_level``
(:func:`vivbench.regression.confidence_set`) used by the window verdicts
(:func:`vivbench.regimes.varying_window_verdicts`).

What this model does not fix: errors in the measured U (a point anemometer
against the tributary-averaged wind the deck feels) smear the bell along U
(the model is therefore fitted on the records' U and yaw smoothed by a Gaussian of
``wind_smoothing_s``, :func:`vivbench.preprocess.smooth_wind`, and weighted by
effective variances, ``eiv_weights``; measured records are evaluated through
:meth:`VaryingCoefficientSINDy.measured_wind`); and it is time-invariant, so
changes the wind does not carry (damping drift, a step between events) are
averaged over (:func:`vivbench.analysis.changes.model_change_scan` checks for them).
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU
from vivbench.io.varying_model import read_varying_model, varying_model_dataset, write_varying_model
from vivbench.library.splines import DEGREE, bspline_basis, bspline_local, difference_penalty, uniform_knots
from vivbench.models.curve_support import EXTRAPOLATED, curves_dataset
from vivbench.models.protocol import ModelBase, as_record, section_names
from vivbench.models.simulate import Simulation
from vivbench.models.varying_simulate import simulate_runs
from vivbench.models.varying_design import design_rows, held_yaw
from vivbench.models.varying_verdicts import (varying_description, varying_settings_text, varying_summary,
                                              varying_window_verdicts)
from vivbench.models.varying_fit import (FINAL_PARAMS, ORDER_SET_MARGIN, ORDER_SUBSETS, PENALTY_CHOICES, event_statistics,
                                         fit_final, fit_shared, settle_smoothing)
from vivbench.models.wind_weights import weighted_section_mean
from vivbench.preprocess.wind_smoothing import smooth_wind
from vivbench.regression.penalised import penalised_rss

# The spline basis, the penalised solve and the order subsets are re-exported from their modules.
__all__ = ["VaryingCoefficientSINDy", "bspline_basis", "bspline_local", "difference_penalty", "uniform_knots", "DEGREE",
           "penalised_rss", "ORDER_SUBSETS", "ORDER_SET_MARGIN", "WIND_SMOOTHING_GRID", "PENALTY_CHOICES",
           "YAW_INSIDE_DEG", "FINAL_PARAMS"]

#: Default candidates of the measured wind's Gaussian smoothing, s (0: none), chosen per campaign by
#: the cross-validated error over events: roughly doubling steps, from the exact wind of an in-library
#: campaign to a point anemometer's slow turbulence.
WIND_SMOOTHING_GRID = (0.0, 15.0, 30.0, 60.0)

#: Degrees: curves at yaw 0 count as inside the data when some fitted sample's yaw came this close to
#: perpendicular (about the direction accuracy of an anemometer).
YAW_INSIDE_DEG = 2.0


class VaryingCoefficientSINDy(ModelBase):
    """Penalised cubic-spline coefficient curves of the powers of A, fitted to a whole campaign.

    dA_k/dt = sum_{i=0..3} a_ki(U_k) A_k^i, a_ki(U) = sum_m c_kim B_m(U)
    (module docstring). A model of the protocol (:mod:`vivbench.models.protocol`):
    ``fit(records)``, ``predict``, ``order_contributions``, ``simulate`` (RK4),
    ``curves`` (docs/concepts.md (coefficient curves), with block-bootstrap bands), ``equations``,
    ``save``/``load`` (NetCDF).

    Parameters
    ----------
    n_basis : sequence of int
        Candidate numbers M of cubic B-splines per curve (M - 3 uniform intervals).
    penalties : sequence of float
        Candidate relative penalties; lambda = penalty * trace(X^T X) / trace(P).
    n_folds : int
        Folds of the cross-validation over events (events are dealt to folds in
        a seeded random order); with fewer events, leave-one-event-out.
    select_orders : bool
        Drop every order whose removal does not raise the cross-validated error
        (backward elimination at the selected M and lambda; order 1 is always kept).
    n_bootstrap : int
        Block-bootstrap replicates of the coefficients (fixed M and lambda) for
        the curves' bands and the window verdicts (0: none).
    block_s : float
        Block length of the bootstrap, s.
    agreement : float
        Share of replicates that must give a window the model's regime for the
        window to count as identifiable (:func:`vivbench.regimes.varying_window_verdicts`).
    tau : float
        Regime threshold of docs/concepts.md (regimes).
    seed : int
        Seed of the fold assignment and of the bootstrap.
    wind_input : {"mean", "section", "additive", "sum"}
        The wind of equation k's curves: the mean of U over the sections
        (default), the section's own U_k, or every section's U_j (and yaw),
        a curve of each summed (module docstring; S times the coefficients, and
        a fit several times slower), or every section's U_j with one curve shared by all, weighted by the
        sections' ``wind_weights`` and summed: a_ki = sum_j w_j f_ki(U_j), the
        same deck at every section, with as many coefficients as "mean".
    yaw_degree : int, 0..3, or None
        Powers j = 1..J of sin^2(psi), psi the mean wind's yaw, whose spline
        curves are added: a_ki(U, psi) = sum_j sin^2j(psi) f_kij(U) (0: the
        wind only). None (default): 1 when every fitted record carries the yaw
        (``Record.yaw``, e.g. from the identification result), else 0 (the
        fitted value is ``yaw_degree_``). A degree > 0 needs records with yaw
        to fit; a record without one is evaluated at the fitted median yaw.
        The curves of docs/concepts.md (coefficient curves) are those at yaw 0.
    wind_smoothing_s : float, s
        Standard deviation of the Gaussian smoothing in time of the fitted
        records' U and yaw (:func:`vivbench.preprocess.smooth_wind`; 0: none),
        which are taken to be measured: a lower mean-wind cut-off against the
        point anemometer's errors-in-variables. Evaluate measured records
        through :meth:`measured_wind` (as ``vivbench pool`` and the method
        API's ``"varying"`` do); records of the deck's own wind (a synthetic
        truth) as they are; fit such records with 0. Default 30 s; with
        ``wind_smoothing_grid``, the prior that the grid's candidates must beat.
    wind_smoothing_grid : sequence of float, s, or None
        Candidate smoothings, chosen per campaign (fitted ``wind_smoothing_s_``)
        by the same cross-validated dA/dt error over folds of events as M and
        lambda: ``wind_smoothing_s`` unless a candidate's is lower by more than
        one standard error (``varying_fit.smoothing_choice``). None (default):
        ``wind_smoothing_s`` as given. :meth:`settle` makes the choice once for
        a selection's models; each fit costs about one fit per candidate.
    model_set_level : float, [0.5, 1)
        Level of the confidence set of order subsets: the models without some
        of the orders 0, 2, 3 (``ORDER_SUBSETS``) whose leave-one-event-out
        prediction error is not significantly above the best subset's (a
        one-sided paired test over events, ``model_set_test``); the window
        verdict needs them all to give the window's regime. Default 0.95; a
        smaller level flags more windows and keeps fewer of them right.
    order_set_margin : float, [0, 1)
        An order subset whose leave-one-event-out error exceeds the best
        subset's by at most this fraction stays in that confidence set even
        when the test finds it significantly worse (default
        ``ORDER_SET_MARGIN``, 0.5 %). Over many events a model outside the
        truth's class can need an order by a fraction of a per cent on every
        event: significant, but it does not identify how the dynamics split
        between the orders, so the verdict must not rest on it.
    model_set_test : {"signed_rank", "z"}
        The paired test of the model set: Wilcoxon's one-sided signed-rank test
        of the per-event differences of held-out loss (default), or the
        z-approximation to their mean. Per-event losses are heavy tailed (a
        long, energetic event's loss is many times a quiet one's), and one
        such event inflates the mean's standard error; the signed-rank test
        uses ranks. A test with fewer than 5 events rejects nothing at
        0.95 (the smallest one-sided p is 2^-n).
    eiv_weights : bool
        Refit at the chosen basis and penalty by weighted least squares with
        effective-variance weights (errors-in-variables of the mean wind): a
        sample's residual variance is s0 + kappa (df/dU)^2 se_U^2, with df/dU
        the first fit's slope in the wind, se_U the spread of the sections'
        (smoothed) anemometers about their mean over sqrt(S) and (s0, kappa)
        fitted to the squared residuals.
        Needs ``wind_input`` "mean" or "additive" (there the variance sums
        every section's wind's, each with the anemometers' spread as its
        error) and two or more sections (else no weights). Default True.
        Costs a second weighted pass at the chosen basis only;
        :meth:`event_statistics` stays unweighted.
    wind_weights : {"modal", "equal"} or sequence of float
        The sections' weights in the mean wind (and yaw) of ``wind_input="mean"``, or of the shared curve of ``"sum"``
        (:mod:`vivbench.models.wind_weights`): ``"modal"`` (default) each
        section's share of the mode's energy, sum_t A_k^2 over the campaign,
        which are the averaged truth's weights L_k phi_k^2 of the linear order
        when the tributary lengths are equal; ``"equal"`` the plain mean; or one
        weight per section (normalised), e.g. L_k phi_k^2 from the bridge's
        drawings.
    penalty_choice : {"cv", "least", "loeo"}
        How the roughness penalty of the fitted curves is chosen at the
        selected basis. ``"cv"`` (default): the minimum of the 5-fold
        cross-validated error of the unweighted fit that chose the basis.
        ``"least"``: the least penalty of the confidence set of penalties
        (leave-one-event-out error of the final, effective-variance weighted
        fit not significantly above the best one's, ``model_set_test`` at
        ``model_set_level``): rougher curves, which follow a sharp lock-in
        bell better where the campaign has the data for it and follow the
        noise where it has not. ``"loeo"``: the best member of that set.
        :func:`vivbench.analysis.varying_selection` chooses between them from
        the campaign's own held-out evidence.
    model_sets : bool
        Compute the confidence sets of order subsets and of penalties
        (leave-one-event-out) that the window verdict requires (default).
        False skips them, for fits made only to predict (the held-out fits
        of :class:`vivbench.analysis.ModelSelection`): such a model gives no
        verdict.

    Attributes
    ----------
    wind_smoothing_s_ : float, s
        The smoothing the model was fitted with (:meth:`measured_wind` applies it).
    wind_smoothing_cv_ : ndarray, shape (n_candidates,)
        Cross-validated error of each candidate smoothing (summed over the
        equations' per-sample errors of the standardised target).
    wind_weights_ : ndarray, shape (S,)
        The sections' weights in the mean wind (summing to 1; equal for files
        written before the weights existed).
    wind_weights_choice_ : str
        What ``wind_weights`` resolved to: "equal", "modal" or "given" (numbers).
    penalty_choice_ : str
        What ``penalty_choice`` resolved to: "cv", "least" or "loeo".
    penalty_cv_ : ndarray, shape (S,)
        The relative penalty at the cross-validated error's minimum (``penalty_``
        is the fitted one; they differ only when ``penalty_choice_`` is "least" or "loeo").
    wind_error_share_ : ndarray, shape (S,)
        With ``eiv_weights``, the share of the first fit's residual variance
        attributed to the mean wind's error (0 without; not saved).
    coef_ : ndarray, shape (S, n_in M_max, 4)
        Physical spline coefficients: a_ki(U) = sum_m coef_[k, m, i] B_km(U), in
        m^(1-i)/s (zero beyond section k's ``n_basis_[k]``). With
        ``wind_input="additive"`` (n_in = S, else 1) entry s M_k + m holds the
        coefficient of B_km(U_s): a_ki = sum_s sum_m coef_[k, s M_k + m, i] B_km(U_s).
    coef_bootstrap_ : ndarray, shape (n_bootstrap, S, M_max, 4)
    knots_ : ndarray, shape (S, M_max + 4), m/s (NaN-padded)
    n_basis_ : ndarray of int, shape (S,)
    penalty_ : ndarray, shape (S,) (relative)
    orders_ : ndarray of bool, shape (S, 4)
        Orders kept in each equation.
    cv_error_ : ndarray, shape (S, len(n_basis), len(penalties))
        Cross-validated mean squared error of the standardised target.
    edf_ : ndarray, shape (S,)
        Effective degrees of freedom, trace((X^T X + lambda P)^-1 X^T X).
    wind_range_ : ndarray, shape (S, 2), m/s
        Range of U_k fitted; the curves are constant outside it.
    y_scale_, a_ref_ : ndarray, shape (S,), m/s and m
        RMS of dA_k/dt and of A_k over the fitted samples (the regression's scales).
    rss_ : ndarray, shape (S,), m^2/s^2
    n_samples_, n_blocks_, n_sections_ : int
    event_ids_ : list of str
    yaw_degree_ : int
        The fitted yaw degree J (``yaw_degree``, or its default from the records).
    coef_yaw_ : ndarray, shape (S, M_max, 4, J)
        Spline coefficients of the yaw terms (coefficients of sin^2j(psi)).
    coef_yaw_bootstrap_ : ndarray, shape (n_bootstrap, S, M_max, 4, yaw_degree)
    yaw_ref_, yaw_fallback_, yaw_min_, yaw_max_ : ndarray, shape (S,)
        RMS, median, minimum and maximum of sin^2(psi) over the fitted samples (outside the last two the
        covariate is held at them, :func:`~vivbench.models.varying_design.held_yaw`).
    subset_coef_, subset_coef_yaw_ : ndarray, shapes (n_subsets,) + those of ``coef_``, ``coef_yaw_``
        The models of every order subset at the selected basis and penalty.
    subset_loeo_ : ndarray, shape (n_subsets, S), m^2/s^2
        Their leave-one-event-out squared prediction errors (summed over events).
    subset_plausible_ : ndarray of bool, shape (n_subsets, S)
        Membership of the confidence set.
    penalty_coef_, penalty_coef_yaw_ : ndarray, shapes (len(penalties),) + those of ``coef_``, ``coef_yaw_``
        The fits at every candidate penalty (selected basis and orders).
    penalty_plausible_ : ndarray of bool, shape (len(penalties), S)
        The confidence set of penalties: leave-one-event-out error not significantly above the best
        penalty's (``model_set_test`` at ``model_set_level``). None (all three) for a model loaded from
        a file written before it.
    """

    _fitted_attribute = "coef_"
    #: Parameters that :meth:`fit_variants` may vary between models fitted together.
    final_params = FINAL_PARAMS

    def __init__(self, *, n_basis: Sequence[int] = (6, 8, 11, 15, 20),
                 penalties: Sequence[float] = tuple(10.0 ** np.arange(-7.0, 1.5, 1.0)),
                 n_folds: int = 5, select_orders: bool = False, n_bootstrap: int = 100,
                 block_s: float = 300.0, agreement: float = 0.9, tau: float = DEFAULT_TAU, seed: int = 0,
                 wind_input: str = "mean", yaw_degree: int | None = None, model_set_level: float = 0.95,
                 order_set_margin: float = ORDER_SET_MARGIN, wind_smoothing_s: float = 30.0,
                 wind_smoothing_grid: Sequence[float] | None = None, eiv_weights: bool = True,
                 model_set_test: str = "signed_rank", wind_weights: str | Sequence[float] = "modal",
                 penalty_choice: str = "cv", model_sets: bool = True):
        self.n_basis = n_basis
        self.penalties = penalties
        self.n_folds = n_folds
        self.select_orders = select_orders
        self.n_bootstrap = n_bootstrap
        self.block_s = block_s
        self.agreement = agreement
        self.tau = tau
        self.seed = seed
        self.wind_input = wind_input
        self.yaw_degree = yaw_degree
        self.model_set_level = model_set_level
        self.order_set_margin = order_set_margin
        self.wind_smoothing_s = wind_smoothing_s
        self.wind_smoothing_grid = wind_smoothing_grid
        self.eiv_weights = eiv_weights
        self.model_set_test = model_set_test
        self.wind_weights = wind_weights
        self.penalty_choice = penalty_choice
        self.model_sets = model_sets

    def wind_inputs(self, U: np.ndarray) -> np.ndarray:
        """The wind each equation's curves are evaluated at, shape (n, S), m/s."""
        U = np.asarray(U, dtype=float)
        if self.wind_input == "mean":
            return np.repeat(self._section_mean(U)[:, None], U.shape[1], axis=1)
        return U

    def _section_mean(self, X: np.ndarray) -> np.ndarray:
        """The weighted mean over the sections (``wind_weights_``) of X (n, S), shape (n,); NaN rows stay NaN."""
        w = getattr(self, "wind_weights_", None)
        if w is None or np.all(w == w[0]):  # equal weights: the plain mean, as before the weights existed
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows stay NaN
                return np.nanmean(X, axis=1)
        return weighted_section_mean(X, w)

    def n_inputs(self, n_sections: int) -> int:
        """Winds that enter each equation: every section's with ``wind_input`` "additive" or "sum", else one."""
        return int(n_sections) if self.wind_input in ("additive", "sum") else 1

    def measured_wind(self, record: Record) -> Record:
        """``record`` with its measured U and yaw smoothed as the model's were at fit (``wind_smoothing_s``).

        For evaluating the model on measured data (verdicts, window regimes, simulations of an identified
        record): the fit saw the measured wind smoothed, a lower cut-off against the point anemometer's
        errors-in-variables. The evaluation methods (:meth:`predict`, :meth:`order_contributions`, ...) take
        a record's wind as given, so a record of the wind the deck itself feels (a synthetic truth) is
        evaluated as it is.
        """
        return smooth_wind(as_record(record), self.fitted_wind_smoothing())

    def settle(self, records: Sequence[Record]) -> tuple[dict, dict]:
        """Settings chosen once on ``records`` for every model of a selection (:func:`settle_smoothing`)."""
        return settle_smoothing(self, records)

    def fitted_wind_smoothing(self) -> float:
        """The wind smoothing of the fit, s: ``wind_smoothing_s_`` once fitted (the cross-validated
        choice from ``wind_smoothing_grid``), before that ``wind_smoothing_s``."""
        return float(getattr(self, "wind_smoothing_s_", self.wind_smoothing_s))

    def yaw_covariate(self, record_or_yaw, n: int) -> np.ndarray | None:
        """The yaw covariate sin^2(psi) of each equation, shape (n, S) (None without ``yaw_degree``).

        With ``wind_input="mean"`` it is the weighted mean over the sections, like the wind.
        A record without yaw gets the median of the fitted samples' (``yaw_fallback_``).
        """
        if self.yaw_degree_ == 0:
            return None
        yaw = record_or_yaw.yaw if isinstance(record_or_yaw, Record) else record_or_yaw
        if yaw is None:
            fallback = getattr(self, "yaw_fallback_", None)
            if fallback is None:
                raise InputError("yaw_degree > 0 needs records with the mean wind's yaw (Record.yaw, e.g. "
                                 "vivbench.analysis.records_from_results of results that store it)")
            return np.broadcast_to(np.asarray(fallback, dtype=float), (n, np.size(fallback))).copy()
        z = np.sin(np.radians(np.asarray(yaw, dtype=float))) ** 2
        if self.wind_input == "mean":
            z = np.repeat(self._section_mean(z)[:, None], z.shape[1], axis=1)
        return z

    def _held_yaw(self, z):
        return held_yaw(z, getattr(self, "yaw_min_", None), getattr(self, "yaw_max_", None),
                        self.wind_input in ("additive", "sum"))

    def to_json(self) -> str:
        """The parameters as a JSON object (sorted keys; sequences as lists)."""
        params = self.get_params()
        params["n_basis"] = [int(x) for x in params["n_basis"]]
        params["penalties"] = [float(x) for x in params["penalties"]]
        params["select_orders"] = bool(params["select_orders"])
        params["yaw_degree"] = None if params["yaw_degree"] is None else int(params["yaw_degree"])
        params["wind_smoothing_s"] = float(params["wind_smoothing_s"])
        grid = params["wind_smoothing_grid"]
        params["wind_smoothing_grid"] = None if grid is None else [float(x) for x in grid]
        params["model_set_level"] = float(params["model_set_level"])
        params["order_set_margin"] = float(params["order_set_margin"])
        params["eiv_weights"] = bool(params["eiv_weights"])
        if not isinstance(params["wind_weights"], str):
            params["wind_weights"] = [float(x) for x in params["wind_weights"]]
        return json.dumps(params, sort_keys=True)

    # -- fitting -------------------------------------------------------------------------------------

    def fit(self, records: Sequence[Record | tuple]) -> "VaryingCoefficientSINDy":
        """Fit the curves of every section (the steps: :mod:`vivbench.models.varying_fit`).

        Parameters
        ----------
        records : sequence of Record (or of legacy (t, A, U, dA) tuples)
            One per event: t shape (n,), s; A, U, dA shape (n, S) in m, m/s, m/s.
            Samples with a non-finite value in a section are ignored for that section.

        Returns
        -------
        self
        """
        fit_final(self, fit_shared(self, records))
        return self

    def fit_variants(self, records: Sequence[Record | tuple], variants: Sequence[dict]) -> list:
        """Fitted copies of this model, one per variant of its :data:`FINAL_PARAMS`, sharing what they share.

        Equal to ``clone.set_params(**variant).fit(records)`` for each variant, but the
        wind smoothing, basis and penalty choice (the costly steps, which those
        parameters do not touch) run once (:func:`vivbench.models.varying_fit.fit_shared`).

        Parameters
        ----------
        records : sequence of Record, as :meth:`fit`
        variants : sequence of dict
            Parameters to set on each copy, names from :data:`FINAL_PARAMS` only
            (e.g. ``{"penalty_choice": "least", "n_bootstrap": 0}``).

        Returns
        -------
        list of VaryingCoefficientSINDy, fitted, in the order of ``variants`` (this model stays unfitted)
        """
        for params in variants:
            other = sorted(set(params) - set(FINAL_PARAMS))
            if other:
                raise InputError(f"fit_variants may change only {', '.join(FINAL_PARAMS)}; got {', '.join(other)}")
        base = type(self)(**self.get_params())
        shared = fit_shared(base, records)
        out = []
        for params in variants:
            model = type(self)(**self.get_params()).set_params(**params)
            fit_final(model, shared)
            out.append(model)
        return out

    def event_statistics(self, records: Sequence[Record]) -> list[dict]:
        """Per-event sufficient statistics of every equation's penalised regression, at the fitted basis and scales.

        What a time-varying use of the model needs (e.g. fitting it separately
        to the events before and after a candidate change,
        :func:`vivbench.analysis.changes.model_change_scan`) without refitting from samples.

        Parameters
        ----------
        records : sequence of Record with dA (with yaw when ``yaw_degree_`` > 0), E of them

        Returns
        -------
        list of dict, one per equation
            ``G`` (E, p, p) and ``b`` (E, p): X_e^T X_e and X_e^T y_e of the
            standardised design and target; ``yy`` (E,); ``n`` (E,) samples;
            ``P`` (p, p) the penalty; ``penalty`` the relative penalty;
            ``keep`` (p,) bool, the kept orders' columns; ``n_basis`` M and
            ``n_inputs`` the wind inputs (S with ``wind_input="additive"``, else
            1): columns ordered (order, yaw power, input, B-spline), so the first
            ``n_inputs`` x M are the constant term's B-splines.
        """
        self._check_fitted()
        return event_statistics(self, [self._check_record(as_record(r, k)) for k, r in enumerate(records)])

    # -- the model protocol --------------------------------------------------------------------------

    def window_verdicts(self, record: Record, window_start, window_end) -> dict:
        """Regime of every window and its verdict (:func:`vivbench.regimes.varying_window_verdicts`)."""
        return varying_window_verdicts(self, record, window_start, window_end)

    def campaign_summary(self) -> dict:
        """What ``vivbench pool`` writes of this model into ``campaign.regimes.nc`` (:func:`vivbench.models.model_summary`)."""
        return varying_summary(self)

    def report_description(self, regimes) -> dict:
        """The report's paragraph on this model and its verdict (:func:`vivbench.models.model_description`)."""
        return varying_description(regimes)

    def event_change_inputs(self, records: Sequence[Record]) -> dict:
        """The model change scan's inputs (:func:`vivbench.models.model_change_inputs`): :meth:`event_statistics`
        of ``records`` and the fit's scales ``a_ref`` (m) and ``y_scale`` (m/s)."""
        return {"statistics": self.event_statistics(records), "a_ref": self.a_ref_, "y_scale": self.y_scale_}

    def for_records(self, records: Sequence[Record]) -> "VaryingCoefficientSINDy":
        """The model itself; refuses records without the wind's yaw when ``yaw_degree`` > 0 (InputError)."""
        if self.yaw_degree and any(as_record(r, k).yaw is None for k, r in enumerate(records)):
            raise InputError("the varying model with a yaw covariate (yaw_degree > 0) needs every "
                             "result to store the wind's yaw (identify it again) or the campaign's event files "
                             "(campaign / --campaign)")
        return self

    def terms_per_equation(self) -> list[int]:
        """Cubic B-splines per curve of each equation (``n_basis_``)."""
        return [int(k) for k in self.n_basis_]

    def settings_text(self) -> str:
        """One line on the fitted settings (:func:`vivbench.models.model_settings_text`)."""
        return varying_settings_text(self)

    def coefficient_values(self, U: np.ndarray, coef: np.ndarray | None = None, yaw=None,
                           coef_yaw: np.ndarray | None = None) -> np.ndarray:
        """The curves a_ki at each equation's wind (and yaw, with ``yaw_degree`` > 0).

        Parameters
        ----------
        U : ndarray, shape (n, S), m/s
        coef : ndarray, shape (S, M_max, 4) or (R, S, M_max, 4), optional
            Spline coefficients at yaw 0 (default ``coef_``).
        yaw : ndarray, shape (n, S), degrees, optional
            The mean wind's yaw (None: 0, see Notes).
        coef_yaw : ndarray, shape (S, M_max, 4, J) or (R, S, M_max, 4, J), optional
            Coefficients of (sin^2 psi)^j, j = 1..J (default ``coef_yaw_`` when
            ``coef`` is None, zeros otherwise).

        Returns
        -------
        ndarray, shape (n, S, 4) or (R, n, S, 4), m^(1-i)/s; NaN where U is not finite.

        Notes
        -----
        ``yaw=None`` means yaw 0 (wind perpendicular to the span): the curves of
        docs/concepts.md (coefficient curves) are defined there. :meth:`order_contributions` passes the
        record's yaw (or the fitted median without one).
        """
        self._check_fitted()
        if coef is None:
            coef = self.coef_
            coef_yaw = self.coef_yaw_ if coef_yaw is None else coef_yaw
        coef = np.asarray(coef, dtype=float)
        U = self.wind_inputs(U)
        J = self.yaw_degree_
        z = None
        if J and yaw is not None and coef_yaw is not None:
            z = self._held_yaw(self.yaw_covariate(np.asarray(yaw, dtype=float), U.shape[0]))
        out = np.zeros(coef.shape[:-3] + (U.shape[0], self.n_sections_, 4))
        n_in = self.n_inputs(self.n_sections_)
        for k in range(self.n_sections_):  # a few sections
            M = int(self.n_basis_[k])
            for s_ in range(n_in):  # additive: the sum over the sections' winds (and yaws)
                u = s_ if n_in > 1 else k
                B = bspline_basis(U[:, u], self.knots_[k, :M + DEGREE + 1])
                cols = slice(s_ * M, (s_ + 1) * M)
                out[..., k, :] += np.einsum("nm,...mi->...ni", B, coef[..., k, cols, :])
                if z is not None:
                    Bz = B[:, :, None] * z[:, u, None, None] ** np.arange(1, J + 1)  # (n, M, J)
                    out[..., k, :] += np.einsum("nmj,...mij->...ni", Bz, np.asarray(coef_yaw)[..., k, cols, :, :])
        return out

    def record_yaw(self, record: Record) -> np.ndarray | None:
        """Yaw in degrees for evaluating on a record: its own, or the fitted median without one (None
        without a yaw covariate)."""
        if not self.yaw_degree_:
            return None
        yaw = record.yaw
        if yaw is not None:
            return yaw
        return np.degrees(np.arcsin(np.sqrt(np.broadcast_to(self.yaw_fallback_, record.A.shape))))

    def replicate_order_contributions(self, record: Record, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Order contributions of bootstrap replicates ``start:stop``, shape (R, n_samples, S, 4), m/s."""
        record = self._check_record(record)
        sl = slice(start, stop)
        return (self.coefficient_values(record.U, self.coef_bootstrap_[sl], self.record_yaw(record),
                                        self.coef_yaw_bootstrap_[sl]) * record.A[..., None] ** np.arange(4))

    def subset_order_contributions(self, record: Record) -> np.ndarray:
        """Order contributions of the models of every order subset (``ORDER_SUBSETS``), shape (n_subsets, n, S, 4), m/s.

        ``subset_plausible_`` (n_subsets, S) says which of them belong to the
        confidence set (leave-one-event-out prediction not significantly worse
        than the best subset's).
        """
        record = self._check_record(record)
        return (self.coefficient_values(record.U, self.subset_coef_, self.record_yaw(record),
                                        self.subset_coef_yaw_) * record.A[..., None] ** np.arange(4))

    def penalty_order_contributions(self, record: Record) -> np.ndarray | None:
        """Order contributions of the fits at every candidate penalty, shape (n_penalties, n, S, 4), m/s.

        ``penalty_plausible_`` (n_penalties, S) says which belong to the confidence set of penalties.
        None for a model loaded from a file written before that set was kept.
        """
        if getattr(self, "penalty_coef_", None) is None:
            return None
        record = self._check_record(record)
        return (self.coefficient_values(record.U, self.penalty_coef_, self.record_yaw(record),
                                        self.penalty_coef_yaw_) * record.A[..., None] ** np.arange(4))

    def order_contributions(self, record: Record) -> np.ndarray:
        """r[:, k, i] = a_ki(U_k) A_k^i, shape (n_samples, n_sections, 4), m/s (NaN where A or U is missing)."""
        record = self._check_record(record)
        return (self.coefficient_values(record.U, yaw=self.record_yaw(record))
                * record.A[..., None] ** np.arange(4))

    def order_contributions_bootstrap(self, record: Record) -> np.ndarray:
        """Order contributions of every bootstrap replicate, shape (n_bootstrap, n_samples, S, 4), m/s."""
        return self.replicate_order_contributions(record)

    def stacked_coefficients(self, coef: np.ndarray | None = None, coef_yaw: np.ndarray | None = None) -> np.ndarray:
        """Spline and yaw coefficients as one vector per equation and order, the layout of :meth:`basis_rows`.

        Parameters
        ----------
        coef : ndarray, shape (..., S, M_max, 4), optional (default ``coef_`` and ``coef_yaw_``)
        coef_yaw : ndarray, shape (..., S, M_max, 4, J), optional (default zeros when ``coef`` is given)

        Returns
        -------
        ndarray, shape (..., S, (J + 1) L, 4), L = ``coef_.shape[1]``
            Entry j L + s M_k + m holds the coefficient of B_m(U_s) (sin^2 psi_s)^j
            (j = 0: ``coef``; j >= 1: ``coef_yaw[..., j - 1]``; s = 0 except
            with ``wind_input="additive"``, where s runs over the sections).
        """
        self._check_fitted()
        if coef is None:
            coef, coef_yaw = self.coef_, self.coef_yaw_
        coef = np.asarray(coef, dtype=float)
        J = self.yaw_degree_
        if coef_yaw is None:
            coef_yaw = np.zeros(coef.shape + (J,))
        blocks = [coef] + [np.asarray(coef_yaw, dtype=float)[..., j] for j in range(J)]
        return np.concatenate(blocks, axis=-2)

    def basis_rows(self, record: Record) -> tuple[np.ndarray, np.ndarray]:
        """The non-zero entries of each sample's design row, for evaluating many coefficient sets at once.

        The curves at sample n are a_ki = sum_q ``vals[n, k, q]`` theta[k, ``cols[n, k, q]``, i]
        with theta from :meth:`stacked_coefficients`, the same values as
        :meth:`coefficient_values` at the record's wind and yaw (cubic B-splines
        have DEGREE + 1 basis functions non-zero at any wind).

        Parameters
        ----------
        record : Record (its wind taken as given, like :meth:`order_contributions`)

        Returns
        -------
        cols : ndarray of int, shape (n, S, (DEGREE + 1) (J + 1) n_in)
            (n_in: S with ``wind_input="additive"``, else 1)
        vals : ndarray, shape (n, S, (DEGREE + 1) (J + 1) n_in), NaN where the curves are undefined (no wind or yaw)
        """
        record = self._check_record(record)
        U = self.wind_inputs(record.U)
        J = self.yaw_degree_
        z = self._held_yaw(self.yaw_covariate(self.record_yaw(record), U.shape[0])) if J else None
        n, S, Lmax = U.shape[0], self.n_sections_, self.coef_.shape[1]
        return design_rows(U, z, self.knots_, self.n_basis_, Lmax, J, self.n_inputs(S))

    def predict(self, record: Record) -> np.ndarray:
        """dA/dt of the model, shape (n_samples, n_sections), m/s."""
        return self.order_contributions(record).sum(axis=-1)

    def simulate(self, record: Record, t0: float | None = None, t1: float | None = None, A0=None,
                 bound_factor: float = 10.0) -> Simulation:
        """Integrate the model from A0 at t0 to t1 on the record's time grid (classical RK4).

        The wind is linear between samples (the curves are evaluated at every
        sample and midpoint at once; only the RK4 steps loop over time).

        Parameters
        ----------
        record : Record
        t0, t1 : float, s, optional
            Span, snapped to the record's samples (default: the whole record).
        A0 : array_like, shape (S,), m, optional
            Initial amplitudes (default: the record's A at t0).
        bound_factor : float
            The run stops when an amplitude leaves [-0.05, bound_factor] x the record's largest amplitude.

        Returns
        -------
        Simulation
        """
        return self.simulate_runs([(record, t0, t1, A0)], bound_factor=bound_factor)[0]

    def simulate_runs(self, runs: Sequence[tuple], bound_factor: float = 10.0) -> list[Simulation]:
        """:meth:`simulate` of several spans at once, ``runs`` a sequence of (record, t0, t1, A0): one batched
        RK4 over the runs (:func:`vivbench.models.varying_simulate.simulate_runs`), each result the same as
        its run's :meth:`simulate`."""
        self._check_fitted()
        return simulate_runs(self, [(self._check_record(r), t0, t1, A0) for r, t0, t1, A0 in runs], bound_factor)

    def curves(self, wind, level: float = 0.95) -> xr.Dataset:
        """The fitted curves a_ki(U) of docs/concepts.md (coefficient curves) with block-bootstrap bands.

        Parameters
        ----------
        wind : array_like, shape (n_wind,), m/s
        level : float
            Level of the percentile band of the bootstrap replicates (widened to
            contain the point curve).

        Returns
        -------
        xarray.Dataset
            ``curves``, ``curves_lower``, ``curves_upper`` (equation, order, wind) in
            m^(1-i)/s; NaN bands without replicates.
        """
        self._check_fitted()
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must lie strictly between 0 and 1; got {level!r}")
        wind = np.atleast_1d(np.asarray(wind, dtype=float))
        if wind.ndim != 1 or not np.all(np.isfinite(wind)):
            raise ValueError("wind must be a 1-D array of finite speeds in m/s")
        Uw = np.repeat(wind[:, None], self.n_sections_, axis=1)
        point = np.moveaxis(self.coefficient_values(Uw), 0, -1)  # (S, 4, n_wind)
        if self.coef_bootstrap_.shape[0]:
            boot = np.moveaxis(self.coefficient_values(Uw, self.coef_bootstrap_), 1, -1)
            q = 50.0 * np.array([1.0 - level, 1.0 + level])
            lo, hi = np.percentile(boot, q, axis=0)
            lower, upper = np.fmin(lo, point), np.fmax(hi, point)
        else:
            lower = upper = np.full_like(point, np.nan)
        ds = curves_dataset(point, lower, upper, wind, band=f"{level:g} bootstrap band", model=type(self).__name__)
        return ds.assign({EXTRAPOLATED: (("equation", "wind"), np.repeat(self.yaw_extrapolated()[:, None], wind.size, axis=1),
                                         {"long_name": "the curve is an extrapolation: the wind's yaw of the curves (0, "
                                          "perpendicular) lies outside the fitted data's yaw"})})

    def yaw_extrapolated(self) -> np.ndarray:
        """Bool (S,): the curves (at yaw 0) are an extrapolation of the yaw covariate.

        True for an equation whose fitted samples never came within ``YAW_INSIDE_DEG`` of a wind
        perpendicular to the span (sin^2 of the yaw always above sin^2 of it); False without a yaw
        covariate, and unknown (False) for a model loaded from a file written before it was kept.
        """
        self._check_fitted()
        zmin = np.asarray(getattr(self, "yaw_min_", np.zeros(self.n_sections_)), dtype=float)
        if not self.yaw_degree_:
            return np.zeros(self.n_sections_, dtype=bool)
        return np.nan_to_num(zmin, nan=0.0) > np.sin(np.radians(YAW_INSIDE_DEG)) ** 2

    def equations(self, precision: int = 3) -> list[str]:
        """Readable equations, e.g. ``"dA1/dt = a10(U1) + a11(U1) A1 + a12(U1) A1^2 + a13(U1) A1^3"``.

        Each curve is summarised by its range over the fitted winds and the
        spline it is (M cubic B-splines, relative penalty, effective degrees of freedom).
        """
        self._check_fitted()
        out = []
        grid = np.linspace(self.wind_range_[:, 0].min(), self.wind_range_[:, 1].max(), 201)
        vals = self.coefficient_values(np.repeat(grid[:, None], self.n_sections_, axis=1))
        for k in range(self.n_sections_):
            terms = []
            for i in range(4):
                if not self.orders_[k, i]:
                    continue
                wind = (f"U1..U{self.n_sections_}" if self.wind_input in ("additive", "sum") else f"U{k + 1}")
                name = f"a{k + 1}{i}({wind})" + ("" if i == 0 else f" A{k + 1}" + ("" if i == 1 else f"^{i}"))
                terms.append(name)
            line = f"dA{k + 1}/dt = " + (" + ".join(terms) if terms else "0")
            ranges = "; ".join(f"a{k + 1}{i} in [{vals[:, k, i].min():.{precision}g}, {vals[:, k, i].max():.{precision}g}]"
                               for i in range(4) if self.orders_[k, i])
            out.append(f"{line}   ({ranges}; {self.n_basis_[k]} cubic B-splines on "
                       f"[{self.wind_range_[k, 0]:.3g}, {self.wind_range_[k, 1]:.3g}] m/s, "
                       f"penalty {self.penalty_[k]:.1e}, edf {self.edf_[k]:.1f})")
        return out

    # -- persistence ---------------------------------------------------------------------------------

    def to_dataset(self) -> xr.Dataset:
        """The fitted model as an xarray Dataset (one variable per fitted array, :mod:`vivbench.io.varying_model`)."""
        self._check_fitted()
        return varying_model_dataset(vars(self), params_json=self.to_json(), equations=section_names(self.n_sections_))

    def save(self, path):
        """Write the fitted model (:mod:`vivbench.io.varying_model`, with its format version) atomically; returns the path."""
        return write_varying_model(self.to_dataset(), path)

    @classmethod
    def load(cls, path) -> "VaryingCoefficientSINDy":
        """A fitted model from a file written by :meth:`save` (any version of the file)."""
        params, fitted = read_varying_model(path, n_subsets=ORDER_SUBSETS.shape[0])
        model = cls(**params)
        for name, value in fitted.items():
            setattr(model, name, value)
        return model
