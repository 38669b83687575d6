"""Choices from the campaign's own evidence: held-out selection among candidate campaign models.

A field campaign has no truth, so every modelling option that changes a campaign
model's class or inputs (a covariate such as the yaw, the wind's smoothing and
weights, penalties, the model class) is chosen here from the campaign's measured
data alone, the same way on a synthetic campaign as on a field one:

1. The events are dealt to ``n_folds`` folds in a seeded random order (with
   fewer events than folds, one event per fold). Every candidate is fitted on
   the other folds' events and predicts each held-out event.
2. The held-out loss of an event is its **output error** by default: each valid
   run of the event's envelope is simulated from its first measured amplitude
   under its measured wind, and the squared differences to the measured
   envelope are summed over samples and sections (m^2). A run that a model
   stops (it left the data's amplitude range) counts every sample after the
   stop as missed by the event's largest measured amplitude. With
   ``criterion="derivative"`` the loss is the squared error of the predicted
   dA/dt against the measured one (the fallback for models that cannot
   simulate).
3. The **confidence set** holds the candidates whose held-out losses are not
   significantly above the best's by either of two paired tests over events:
   the summed difference to the best is at most one standard error of its sum
   (a one-standard-error rule), and a one-sided Wilcoxon signed-rank test of the
   per-event differences does not reject at :data:`RANK_LEVEL`
   (:func:`vivbench.analysis.confidence_set`). The second test keeps a few
   events with large losses from hiding a candidate that is worse on nearly
   every event.
4. The model reported is the **simplest** of the set (the lowest complexity,
   ties to the lower loss), so that a covariate or a rougher fit enters only
   where the campaign's own data demand it. The candidates are scored by
   complexity in a forward search: those of the two lowest complexities
   first, those of the next one only while the choice is of the highest
   complexity scored so far (a yaw polynomial of degree 2 is tried only where
   degree 1 was needed). Candidates never scored are recorded as such.

The verdict of the selected model (:meth:`ModelSelection.identifiable`) flags a
window only when its own verdict does, when every model of the confidence set
gives the window the same regime, and when the regime survives refits of the
chosen candidate with the measured wind perturbed by its estimated error
(:func:`wind_error_scale`): errors in the wind bias every bootstrap replicate
alike, so the bootstrap alone cannot see them.

With a **null model** (``null_model``; :func:`varying_selection` uses the quasi-steady map
:class:`vivbench.models.QuasiSteadyAmplitude`, A_k = g_k(U)), the null is scored on the same folds,
and the verdict flags no window at all unless the null falls outside the confidence set: where
the dynamic candidates do not predict held-out events significantly better than an amplitude that
follows the wind with no dynamics (a forced response, an envelope driven by buffeting, errors in
the wind that drown the amplitude's own changes), any split of the dynamics between the orders of A
fits, and the regimes are not identified from the campaign. With too few events for held-out
evidence (fewer than :data:`MIN_EVENTS`) nothing is flagged either. With ``wind_bins``, the same test
is also made by wind (:mod:`vivbench.analysis.wind_local`): a window is flagged only where its wind
lies in a bin in which the chosen model's held-out error is significantly below the null's.

With the **stationarity test** (``change_scan=True``, the default of :func:`varying_selection`), the
chosen model's own change scan (:func:`vivbench.analysis.changes.statistics_change_scan`: refits before
and after every split of the events in time order, permutation p-value) is run once it is fitted to
every event. A located change means that one function of (A, U) does not hold for the whole campaign:
the model averages over a structural change (a damping step) or misfits some events differently from
the others, so its regimes are not those of any one period, and no window is flagged. The alarm, its
p-value and the first event after the located change are recorded in the evidence.

The **envelope's time constant** of the campaign (``time_constant_s_``) is read from the chosen
model: -1 / the median slope d(dA/dt)/dA of its dA/dt over the windows it flags as regime 1 (no
self-excitation: the amplitude relaxes to the wind's forcing at that rate). An event that lasts only
a few time constants shows an amplitude's growth or decay but not how it ends, and the split of that
change between the orders of A, which decides the limit regimes 3 and 4, is then not identified by
the event. The evidence lists the events shorter than ``min_time_constants`` time constants
(:data:`LIMIT_TIME_CONSTANTS` in :func:`varying_selection`), and no window of such an event is flagged
with a limit regime; with ``min_time_constants`` None, the events shorter than
:data:`LIMIT_TIME_CONSTANTS` are listed and nothing is withheld.
"""

from __future__ import annotations

import json
import math
from typing import Sequence

import numpy as np
import xarray as xr

from vivbench.core.errors import InputError
from vivbench.core.parallel import run_tasks
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU
from vivbench.analysis.candidates import Candidate, settle_candidates, without_yaw
from vivbench.analysis.held_out import (CRITERIA, RANK_LEVEL, confidence_set, dynamics_by_wind, event_folds, fit_task,
                                        held_out_task, one_se_set, shared_groups, variant_params)
from vivbench.analysis.time_constant import envelope_time_constant, short_events, valid_span
from vivbench.analysis.selection_text import evidence_text
from vivbench.analysis.wind_error import SINGLE_SECTION_SHARE, perturbed_wind, wind_error_scale
from vivbench.analysis.wind_local import WIND_BINS, window_wind, wind_bin_edges, wind_bins_of
from vivbench.models.model_input import measured_input
from vivbench.models.protocol import as_record, model_change_inputs, model_summary
from vivbench.preprocess.unmeasured_wind import shifted_unmeasured_wind
from vivbench.regimes.model import model_verdicts, model_window_regimes

__all__ = ["Candidate", "ModelSelection", "LIMIT_TIME_CONSTANTS", "MIN_EVENTS", "MODEL_CLASSES", "STRUCTURAL_OPTIONS",
           "UNMEASURED_Z", "VARYING_OPTIONS", "VARYING_PRIORS", "SINGLE_SECTION_SHARE", "perturbed_wind",
           "varying_selection", "wind_error_scale", "without_yaw"]

#: Fewest events for a held-out choice among several candidates (every training set keeps two events).
MIN_EVENTS = 3

#: Events shorter than this many envelope time constants are listed in the evidence as too short to
#: show how an amplitude's change ends (module docstring; a stated prior, docs/limitations.md).
LIMIT_TIME_CONSTANTS = 5.0

class ModelSelection:
    """A campaign model chosen among candidates by held-out prediction with whole events left out.

    A model of the protocol itself: after :meth:`fit`, ``predict``, ``simulate``,
    ``order_contributions``, ``curves``, ``measured_wind`` and ``save`` are those of the
    chosen candidate fitted to every event (``model_``), and :meth:`identifiable` is its
    verdict narrowed to the windows every model of the confidence set and every
    wind-perturbed refit agree on (module docstring).

    Parameters
    ----------
    candidates : sequence of Candidate
        At least one; names unique. A single candidate is fitted without held-out runs.
    n_folds : int, >= 2
        Folds of events (fewer events: one event per fold).
    criterion : {"output", "derivative"}
        Held-out loss (module docstring).
    n_perturbations : int, >= 0
        Refits of the chosen candidate on winds perturbed by their estimated error
        (:func:`wind_error_scale`, :func:`perturbed_wind`) whose regimes the verdict must
        match (0: none).
    perturbation_timescale_s : float, s
        Time scale of the wind's perturbation and of its error estimate.
    tau : float
        Regime threshold of the set and perturbation agreement.
    verdict : callable or None
        ``verdict(model, record, window_start, window_end)`` -> dict with ``regime`` and ``identifiable``
        (W, S), to replace the chosen model's own verdict; None: the model's own through the protocol
        (:func:`vivbench.regimes.model_verdicts`: its ``window_verdicts``, else the regime rule with its
        ``identifiable``, else no window flagged), whatever the class of the chosen candidate.
    seed : int
        Seed of the folds and of the perturbations.
    workers : int
        Local processes for the held-out fits (1: in this process).
    scheduler : str or None
        A dask scheduler address instead (see :func:`vivbench.core.parallel.run_tasks`).
    null_model : object or None
        An unfitted model with ``fit`` and ``simulate`` (``predict`` for the derivative criterion) that
        has no dynamics of its own, scored on the same folds (module docstring); None: no null test.
    change_scan : bool
        Run the chosen model's change scan once it is fitted to every event, and flag no window when it
        locates a change (module docstring); models without per-event statistics
        (:func:`vivbench.models.model_change_inputs` gives None) are not scanned.
    single_section_share : float, in [0, 1)
        The wind error of a campaign with one section, as a share of each event's mean wind
        (:func:`wind_error_scale`; default :data:`SINGLE_SECTION_SHARE`, a stated prior).
    wind_bins : int or None, >= 1
        With a null model: also test it in this many bins of the measured wind (equal shares of the
        samples), and flag a window only where its wind lies in a bin in which the chosen model's held-out
        error is significantly below the null's (:mod:`vivbench.analysis.wind_local`); None: the
        campaign-wide test alone.
    rank_level : float or None, in (0, 1)
        Level of the confidence set's signed-rank test (:func:`vivbench.analysis.confidence_set`);
        None: the one-standard-error rule alone.
    min_time_constants : float or None, > 0
        Flag no window with a limit regime (3 or 4) in an event shorter than this many envelope time
        constants ``time_constant_s_`` (module docstring), nor any in a campaign whose time constant
        is not identified; None: no such restriction (the short events are still listed in the evidence).

    Attributes
    ----------
    model_ : the chosen candidate fitted to every event
    chosen_ : str, its name
    names_ : list of str, the candidates' names
    note_ : str, why no held-out choice was made ("" when it was)
    losses_ : ndarray, shape (C, E), held-out loss of every candidate on every event (NaN where not scored)
    in_set_ : ndarray of bool, shape (C,), the confidence set (False where not scored)
    excess_, se_ : ndarray, shape (C,), summed loss above the best's and its standard error (NaN where not scored)
    p_rank_ : ndarray, shape (C,), the signed-rank test's p-value against the best (NaN where not scored)
    scored_ : ndarray of bool, shape (C,), the candidates scored on held-out events (the forward search)
    set_models_ : list of fitted models of the set other than the chosen (n_bootstrap 0)
    perturbed_models_ : list of fitted models of the chosen candidate on perturbed winds
    wind_error_ : ndarray, shape (E, S), m/s, the estimated wind error of every event
    null_loss_ : ndarray, shape (E,), the null model's held-out loss (NaN without one or without folds)
    null_in_set_ : bool or None, whether the null is in the confidence set (None: not tested)
    dynamics_shown_ : bool, whether the null test lets the verdict flag windows (module docstring)
    change_ : dict, the chosen model's change scan: ``tested``, ``detected``, ``p_value``, ``event``
        (the first event after the located change, "" when none)
    stationary_ : bool, whether the change scan lets the verdict flag windows (True when not tested)
    change_scan_ : dict or None, the change scan itself (None when not run): ``events`` (the event ids
        scanned, in order), ``seed``, ``inputs`` (:func:`vivbench.models.model_change_inputs` of the
        chosen model on the records' wind as at fit) and ``scan``
        (:func:`vivbench.analysis.changes.statistics_change_scan` of them), which ``vivbench pool``
        writes instead of scanning again
    event_ids_ : list of str
    time_constant_s_ : float, s, the envelope's time constant (NaN: the chosen model flags no regime-1
        window, or gives no dA/dt)
    event_duration_s_ : ndarray, shape (E,), s, each event's longest stretch of valid samples (:func:`valid_span`)
    """

    def __init__(self, *, candidates: Sequence[Candidate], n_folds: int = 5, criterion: str = "output",
                 n_perturbations: int = 2, perturbation_timescale_s: float = 60.0, tau: float = DEFAULT_TAU,
                 verdict=None, seed: int = 0, workers: int = 1, scheduler: str | None = None,
                 null_model=None, change_scan: bool = False, single_section_share: float = SINGLE_SECTION_SHARE,
                 min_time_constants: float | None = None, rank_level: float | None = RANK_LEVEL,
                 wind_bins: int | None = None):
        self.candidates = tuple(candidates)
        self.wind_bins = wind_bins
        self.rank_level = rank_level
        self.min_time_constants = min_time_constants
        self.single_section_share = single_section_share
        self.null_model = null_model
        self.change_scan = change_scan
        self.n_folds = n_folds
        self.criterion = criterion
        self.n_perturbations = n_perturbations
        self.perturbation_timescale_s = perturbation_timescale_s
        self.tau = tau
        self.verdict = verdict
        self.seed = seed
        self.workers = workers
        self.scheduler = scheduler

    def _validate(self) -> None:
        if not self.candidates:
            raise InputError("a model selection needs at least one candidate")
        if not all(isinstance(c, Candidate) for c in self.candidates):
            raise InputError("candidates must be Candidate objects (name, model, complexity)")
        names = [c.name for c in self.candidates]
        if len(set(names)) != len(names):
            raise InputError(f"candidate names must be unique; got {names}")
        if int(self.n_folds) != self.n_folds or self.n_folds < 2:
            raise InputError(f"n_folds must be an integer >= 2; got {self.n_folds!r}")
        if self.criterion not in CRITERIA:
            raise InputError(f"criterion must be one of {', '.join(map(repr, CRITERIA))}; got {self.criterion!r}")
        if int(self.n_perturbations) != self.n_perturbations or self.n_perturbations < 0:
            raise InputError(f"n_perturbations must be an integer >= 0; got {self.n_perturbations!r}")
        share = self.single_section_share
        if not (isinstance(share, (int, float)) and math.isfinite(share) and 0.0 <= share < 1.0):
            raise InputError(f"single_section_share must be a number in [0, 1) (a share of the mean wind); got {share!r}")
        nb = self.wind_bins
        if nb is not None and not (isinstance(nb, int) and not isinstance(nb, bool) and nb >= 1):
            raise InputError(f"wind_bins must be None or an integer >= 1; got {nb!r}")
        lv = self.rank_level
        if lv is not None and not (isinstance(lv, (int, float)) and 0.0 < lv < 1.0):
            raise InputError(f"rank_level must be None or a level in (0, 1); got {lv!r}")
        k = self.min_time_constants
        if k is not None and not (isinstance(k, (int, float)) and math.isfinite(k) and k > 0):
            raise InputError(f"min_time_constants must be None or a positive number of time constants; got {k!r}")
        if not (np.isfinite(self.perturbation_timescale_s) and self.perturbation_timescale_s > 0):
            raise InputError(f"perturbation_timescale_s must be a positive number of seconds; "
                             f"got {self.perturbation_timescale_s!r}")

    def fit(self, records: Sequence[Record]) -> "ModelSelection":
        """Choose among the candidates on held-out events, then fit the choice (and its checks) to every event.

        The settings that the simplest candidate settles on every event first (e.g. the varying model's wind
        smoothing, :func:`vivbench.analysis.candidates.settle_candidates`) hold for every model of the fit.

        Parameters
        ----------
        records : sequence of Record, one per event (A, U, dA of shape (n, S) in m, m/s, m/s)

        Returns
        -------
        self
        """
        self._validate()
        records = [as_record(r, k) for k, r in enumerate(records)]
        given = self.candidates, self.null_model
        self.candidates, self.null_model, self.settled_evidence_ = settle_candidates(*given, records)
        try:
            return self._fit(records)
        finally:  # the parameters stay those given (a refit on other records settles again)
            self.candidates, self.null_model = given

    def _fit(self, records: list[Record]) -> "ModelSelection":
        C, E = len(self.candidates), len(records)
        self.names_ = [c.name for c in self.candidates]
        self.event_ids_ = [r.event_id for r in records]
        self.losses_ = np.zeros((C, E))
        self.note_ = ""
        null = self.null_model
        self.null_loss_ = np.full(E, np.nan)
        self.null_in_set_ = None
        self.binned_losses_, self.wind_edges_ = {}, None
        if (C > 1 or null is not None) and E < MIN_EVENTS:
            # Leaving events out would leave a single event to fit: no evidence, the simplest candidate.
            self.losses_[:] = np.nan
            self.note_ = (f"{E} events: too few for a held-out choice (at least {MIN_EVENTS}); "
                          "the simplest candidate is used"
                          + ("" if null is None else ", and with no held-out evidence of the dynamics "
                             "no window is flagged"))
            self.in_set_, self.excess_, self.se_ = np.ones(C, dtype=bool), np.zeros(C), np.zeros(C)
            self.p_rank_, self.scored_ = np.ones(C), np.zeros(C, dtype=bool)
        elif C > 1 or null is not None:
            self._score(records, null)
        else:
            self.in_set_, self.excess_, self.se_ = np.ones(1, dtype=bool), np.zeros(1), np.zeros(1)
            self.p_rank_, self.scored_ = np.ones(1), np.ones(1, dtype=bool)
        # The dynamics are shown only when the dynamic models predict held-out events significantly better
        # than the null model (the quasi-steady map); with too few events for held-out evidence, they are not.
        if null is None:
            self.dynamics_shown_ = True
        else:
            self.dynamics_shown_ = self.null_in_set_ is False
        chosen = self._simplest()
        self.chosen_index_ = chosen
        self.chosen_ = self.names_[chosen]
        binned = getattr(self, "binned_losses_", {})
        self.dynamics_by_wind_ = None
        if chosen in binned and C in binned:
            self.dynamics_by_wind_ = dynamics_by_wind(binned[chosen], binned[C], MIN_EVENTS)
        members = np.flatnonzero(self.in_set_)
        rng = np.random.default_rng([int(self.seed), 1])
        self.wind_error_ = np.stack([wind_error_scale(r, self.perturbation_timescale_s, self.single_section_share)
                                     for r in records])
        perturbed = [[perturbed_wind(r, s, self.perturbation_timescale_s, rng)
                      for r, s in zip(records, self.wind_error_)] for _ in range(int(self.n_perturbations))]
        others = [i for i in members if i != chosen]
        # The final fits, in parallel: the choice itself, the set's other members and the perturbed refits;
        # the choice and the members that differ from it only in final parameters are fitted together.
        finals = [chosen] + others
        groups = shared_groups([self.candidates[i].model for i in finals])
        tasks = ([{"model": self.candidates[finals[g[0]]].model,
                   "variants": [variant_params(self.candidates[finals[j]].model, **({} if j == 0 else {"n_bootstrap": 0}))
                                for j in g], "records": records} for g in groups]
                 + [{"model": self.candidates[chosen].model,
                     "variants": [variant_params(self.candidates[chosen].model, n_bootstrap=0)], "records": p}
                    for p in perturbed])
        slots = groups + [[len(finals) + k] for k in range(len(perturbed))]  # the fits' places in ``fitted``
        fitted = [None] * (len(finals) + len(perturbed))
        for out in run_tasks(fit_task, tasks, workers=int(self.workers), scheduler=self.scheduler):
            if out.error is not None:
                raise InputError(f"the final fit {out.index} of the selection failed: {out.error}")
            for j, model in zip(slots[out.index], out.value):
                fitted[j] = model
        self.model_ = fitted[0]
        self.set_models_ = fitted[1:1 + len(others)]
        self.perturbed_models_ = fitted[1 + len(others):]
        self.change_ = self._change_scan(records)
        self.stationary_ = not self.change_["detected"]
        self.event_duration_s_ = np.array([valid_span(r) for r in records])
        self.time_constant_s_ = envelope_time_constant(self.model_, records, self._own_verdict,
                                                       lambda r: measured_input(self.model_, r))
        return self

    def _scored(self) -> np.ndarray:
        """Which candidates were scored on held-out events, shape (C,)."""
        return getattr(self, "scored_", np.ones(len(self.candidates), dtype=bool))

    def _p_rank(self) -> np.ndarray:
        """The signed-rank p-values of the candidates, shape (C,) (NaN where not computed)."""
        return getattr(self, "p_rank_", np.full(len(self.candidates), np.nan))

    def _simplest(self) -> int:
        """Index of the simplest member of the confidence set (lowest complexity, ties to the lower loss)."""
        complexity = np.array([c.complexity for c in self.candidates])
        total = np.where(self._scored(), np.nan_to_num(self.losses_.sum(axis=1)), np.inf)
        return int(min(np.flatnonzero(self.in_set_), key=lambda i: (complexity[i], total[i], i)))

    def _score(self, records: list[Record], null) -> None:
        """Held-out losses, level by level of complexity, and the confidence set of the scored candidates.

        The candidates of the two lowest complexities (and the null model) are scored first; those of the
        next complexity only while the choice among the scored ones is of the highest complexity scored
        (forward selection: a further term is tried only where the previous one was needed).
        """
        C, E = len(self.candidates), len(records)
        fold = event_folds(E, self.n_folds, self.seed)
        complexity = np.array([c.complexity for c in self.candidates])
        levels = sorted(set(complexity.tolist()))
        self.scored_ = np.zeros(C, dtype=bool)
        self.losses_[:] = np.nan
        local = null is not None and self.wind_bins is not None
        self.wind_edges_ = wind_bin_edges(records, self.wind_bins) if local else None
        binned = {}
        n_levels = min(2, len(levels))
        todo = list(np.flatnonzero(complexity <= levels[n_levels - 1])) + ([C] if null is not None else [])
        while True:
            models = [self.candidates[i].model if i < C else null for i in todo]
            groups = shared_groups(models)
            # one task per (group, fold), the workers sharing a level's fits evenly; fitted to predict only
            # (no bootstrap, no confidence sets of the verdict)
            n_fold = int(fold.max()) + 1
            tasks = [{"model": models[g[0]], "records": records, "fold": fold, "folds": [f],
                      "variants": [variant_params(models[i], n_bootstrap=0, model_sets=False) for i in g],
                      "criterion": self.criterion, "wind_edges": self.wind_edges_}
                     for g in groups for f in range(n_fold)]
            self.scored_[[i for i in todo if i < C]] = True
            binned.update({i: np.zeros((E, len(self.wind_edges_) - 1)) for i in todo} if local else {})
            for out in run_tasks(held_out_task, tasks, workers=int(self.workers), scheduler=self.scheduler):
                group = groups[out.index // n_fold]
                if out.error is not None:
                    name = ", ".join(self.candidates[todo[i]].name if todo[i] < C else "the quasi-steady null model"
                                     for i in group)
                    raise InputError(f"{name!r} failed on a held-out fold: {out.error}")
                held = fold == tasks[out.index]["folds"][0]
                for j, (i, loss) in enumerate(zip(group, out.value["loss"])):
                    if local:
                        binned[todo[i]][held] = out.value["binned"][j][held]
                    if todo[i] < C:
                        self.losses_[todo[i], held] = loss[held]
                    else:
                        self.null_loss_[held] = loss[held]
            idx = np.flatnonzero(self.scored_)
            if self.rank_level is None:
                in_set, excess, se = one_se_set(self.losses_[idx])
                p = np.full(idx.size, np.nan)
            else:
                in_set, excess, se, p = confidence_set(self.losses_[idx], rank_level=float(self.rank_level))
            self.in_set_ = np.zeros(C, dtype=bool)
            self.excess_, self.se_, self.p_rank_ = np.full(C, np.nan), np.full(C, np.nan), np.full(C, np.nan)
            self.in_set_[idx], self.excess_[idx], self.se_[idx], self.p_rank_[idx] = in_set, excess, se, p
            if n_levels == len(levels) or complexity[self._simplest()] < levels[n_levels - 1]:
                break
            todo = list(np.flatnonzero(complexity == levels[n_levels]))
            n_levels += 1
        self.binned_losses_ = binned  # candidate index (C: the null) -> (E, B) losses by wind bin
        if null is not None:
            with_null = one_se_set(np.vstack([self.losses_[idx], self.null_loss_[None]]))
            self.null_in_set_ = bool(with_null[0][-1])
            self.null_excess_, self.null_se_ = float(with_null[1][-1]), float(with_null[2][-1])

    def _short_threshold(self) -> float:
        """Time constants an event must last: ``min_time_constants``, or the prior when it is None."""
        return LIMIT_TIME_CONSTANTS if self.min_time_constants is None else float(self.min_time_constants)

    def short_events(self) -> list[str]:
        """The events shorter than ``min_time_constants`` (or, when None, :data:`LIMIT_TIME_CONSTANTS`)
        envelope time constants; all when the time constant is not identified."""
        self._check_fitted()
        return short_events(self.event_ids_, self.event_duration_s_, self.time_constant_s_, self._short_threshold())

    def _narrowed(self, record: Record, window_start, window_end, regime: np.ndarray) -> np.ndarray:
        """Windows (W, S) whose ``regime`` every check beyond the chosen model's own verdict lets stand: none without
        dynamics shown (the null test) or with a located change; else :meth:`agreement`'s, at a wind where the
        dynamics were shown (``wind_bins``), no limit regime (3, 4) in an event shorter than ``min_time_constants``."""
        if not (getattr(self, "dynamics_shown_", True) and getattr(self, "stationary_", True)):
            return np.zeros(np.shape(regime), dtype=bool)
        ok = self.agreement(record, window_start, window_end, regime)
        local = getattr(self, "dynamics_by_wind_", None)
        if local is not None:
            U = window_wind(measured_input(self.model_, record).U, record.t, window_start, window_end)
            b = wind_bins_of(U, self.wind_edges_)
            ok = ok & (b >= 0) & local[0][np.maximum(b, 0)]
        k = self.min_time_constants
        tc = getattr(self, "time_constant_s_", float("nan"))
        if k is None or (math.isfinite(tc) and valid_span(record) >= k * tc):
            return ok
        return ok & (np.asarray(regime) < 3)

    def _change_scan(self, records: list[Record]) -> dict:
        """The chosen model's change scan on the campaign's events (module docstring); keeps its inputs and
        whole result in ``change_scan_`` (None when not scanned)."""
        from vivbench.analysis.changes import statistics_change_scan

        out = {"tested": False, "detected": False, "p_value": float("nan"), "event": ""}
        self.change_scan_ = None
        if not self.change_scan:
            return out
        # on the wind as the model saw it at fit, as vivbench pool's own scan of the model
        inputs = model_change_inputs(self.model_, [measured_input(self.model_, r) for r in records])
        if inputs is None:
            return out
        scan = statistics_change_scan(inputs["statistics"], seed=int(self.seed))
        self.change_scan_ = {"events": list(self.event_ids_), "seed": int(self.seed), "inputs": inputs, "scan": scan}
        out["tested"] = bool(np.isfinite(scan["p_value"]))
        out["detected"] = bool(scan["detected"])
        out["p_value"] = float(scan["p_value"])
        if scan["detected"]:
            out["event"] = str(self.event_ids_[int(scan["change_index"])])
        return out

    def recorded_change_scan(self) -> dict | None:
        """The chosen model's change scan run at fit, ``change_scan_`` (:func:`vivbench.models.recorded_change_scan`)."""
        self._check_fitted()
        return self.change_scan_

    # -- the protocol, through the chosen model ------------------------------------------------------

    def _check_fitted(self) -> None:
        if not hasattr(self, "model_"):
            raise InputError("this ModelSelection is not fitted: call fit(records) first")

    def __getattr__(self, name):
        # Everything else (predict, simulate, order_contributions, curves, measured_wind, equations, save, ...)
        # is the chosen model's. Fitted attributes of the selection itself are found before this is called.
        if name.startswith("_") or name in ("model_", "candidates"):
            raise AttributeError(name)
        model = self.__dict__.get("model_")
        if model is None:
            raise AttributeError(name)
        return getattr(model, name)

    def _regimes(self, model, record: Record, window_start, window_end) -> np.ndarray:
        rec = measured_input(model, record)
        own = getattr(model, "window_regimes", None)
        if callable(own):
            return np.asarray(own(rec, window_start, window_end), dtype=int)
        return model_window_regimes(model, rec, window_start, window_end, tau=self.tau)["regime"].astype(int)

    def _own_verdict(self, record: Record, window_start, window_end) -> dict:
        """The chosen model's verdict on the measured record (the last one kept: regimes and flags ask in turn)."""
        start = np.atleast_1d(np.asarray(window_start, dtype=float))
        end = np.atleast_1d(np.asarray(window_end, dtype=float))
        key = (id(record), start.tobytes(), end.tobytes())
        last = self.__dict__.get("_last_verdict")
        if last is not None and last[0] == key and last[1] is record:
            return last[2]
        rec = measured_input(self.model_, record)
        if self.verdict is not None:
            out = dict(self.verdict(self.model_, rec, start, end))
        else:  # the model's own, through the protocol (its window_verdicts, or the rule and its identifiable)
            out = model_verdicts(self.model_, rec, start, end, tau=self.tau)
        self.__dict__["_last_verdict"] = (key, record, out)
        return out

    def chosen_model(self):
        """The chosen candidate, fitted to every event (:func:`vivbench.models.chosen_model`)."""
        self._check_fitted()
        return self.model_

    @property
    def measured_wind(self):
        """The chosen model's ``measured_wind`` (before the fit the first candidate's); AttributeError when
        the models take a record's wind as given."""
        model = self.__dict__.get("model_")
        return (self.candidates[0].model if model is None else model).measured_wind

    def measured_verdicts(self, record: Record, window_start, window_end) -> dict:
        """The chosen model's verdicts (:func:`vivbench.regimes.model_verdicts`) on the measured record,
        ``identifiable`` narrowed to :meth:`agreement`'s windows (the verdict ``vivbench pool`` writes)."""
        self._check_fitted()
        out = model_verdicts(self.model_, measured_input(self.model_, record), window_start, window_end, tau=self.tau)
        # Every model of the confidence set and every wind-perturbed refit must give the window's regime.
        out["identifiable"] = out["identifiable"] & self._narrowed(record, window_start, window_end, out["regime"])
        return out

    def for_records(self, records: Sequence[Record]) -> "ModelSelection":
        """The selection to fit on ``records``: without the candidates that need the wind's yaw when a record
        carries none (:func:`without_yaw`)."""
        return without_yaw(self) if any(r.yaw is None for r in records) else self

    def campaign_summary(self) -> dict:
        """The chosen model's :func:`vivbench.models.model_summary` with the attribute ``selection_json``
        (:meth:`evidence`)."""
        self._check_fitted()
        out = model_summary(self.model_)
        return {**out, "attrs": {**out["attrs"], "selection_json": json.dumps(self.evidence(), sort_keys=True)}}

    def window_regimes(self, record: Record, window_start, window_end) -> np.ndarray:
        """Regime of every window (W, S) by the chosen model, on the record's wind as at fit."""
        self._check_fitted()
        return np.asarray(self._own_verdict(record, window_start, window_end)["regime"], dtype=int)

    def agreement(self, record: Record, window_start, window_end, regime: np.ndarray | None = None) -> np.ndarray:
        """Windows (W, S) on which every other member of the confidence set and every perturbed refit give
        ``regime`` (default: the chosen model's), and, where the record's wind was taken from anemometers
        elsewhere on the span (``Record.wind_distance`` > 0), the chosen model too with those sections'
        winds shifted by -+ ``UNMEASURED_Z`` times their error (:func:`vivbench.preprocess.shifted_unmeasured_wind`)."""
        self._check_fitted()
        ref = self.window_regimes(record, window_start, window_end) if regime is None else np.asarray(regime)
        ok = np.ones(ref.shape, dtype=bool)
        for m in list(self.set_models_) + list(self.perturbed_models_):
            ok &= self._regimes(m, record, window_start, window_end) == ref
        smoothing = float(getattr(self.model_, "fitted_wind_smoothing", lambda: 0.0)())
        for z in (-UNMEASURED_Z, UNMEASURED_Z):  # winds not measured at their sections: the regime within their error
            shifted = shifted_unmeasured_wind(record, smoothing, z)
            if shifted is not None:
                ok &= self._regimes(self.model_, shifted, window_start, window_end) == ref
        return ok

    def identifiable(self, record: Record, window_start, window_end) -> np.ndarray:
        """The chosen model's verdict (W, S) narrowed to :meth:`agreement`'s windows."""
        self._check_fitted()
        own = self._own_verdict(record, window_start, window_end)
        flag = np.asarray(own["identifiable"], dtype=bool)
        return flag & self._narrowed(record, window_start, window_end, own["regime"])

    def curves(self, wind, level: float = 0.95) -> xr.Dataset:
        """The chosen model's curves, their bands widened to hold every other member of the confidence set.

        A covariate that the campaign's data cannot tell from something else (a yaw that follows the
        same course in every event) then widens the bands instead of bending the curves unseen.

        Parameters
        ----------
        wind : array_like, shape (n_wind,), m/s
        level : float, the level of the chosen model's own bands

        Returns
        -------
        xarray.Dataset, as the chosen model's ``curves`` (``curves``, ``curves_lower``, ``curves_upper``
        (equation, order, wind) in m^(1-i)/s), with the attribute ``confidence_set`` (JSON list of names)
        """
        self._check_fitted()
        out = self.model_.curves(wind, level=level)
        lower, upper = out["curves_lower"].values.copy(), out["curves_upper"].values.copy()
        point = out["curves"].values
        lower = np.where(np.isfinite(lower), lower, point)
        upper = np.where(np.isfinite(upper), upper, point)
        for m in self.set_models_:
            c = m.curves(wind, level=level)["curves"].values
            lower, upper = np.fmin(lower, c), np.fmax(upper, c)
        out["curves_lower"] = (out["curves_lower"].dims, lower, out["curves_lower"].attrs)
        out["curves_upper"] = (out["curves_upper"].dims, upper, out["curves_upper"].attrs)
        out.attrs["confidence_set"] = json.dumps([n for n, ok in zip(self.names_, self.in_set_) if ok])
        return out

    # -- the evidence ----------------------------------------------------------------------------------

    def evidence(self) -> dict:
        """The held-out evidence of the choice as plain data (JSON-ready)."""
        self._check_fitted()
        return {
            "criterion": self.criterion, "n_folds": int(min(self.n_folds, len(self.event_ids_))), "chosen": self.chosen_,
            "candidates": [
                {"name": c.name, "complexity": int(c.complexity), "options": c.options or {},
                 "params": _json_params(c.model),
                 "held_out_loss": float(self.losses_[i].sum()), "excess": float(self.excess_[i]),
                 "se": float(self.se_[i]), "p_rank": float(self._p_rank()[i]), "scored": bool(self._scored()[i]),
                 "in_set": bool(self.in_set_[i])}
                for i, c in enumerate(self.candidates)],
            "events": list(self.event_ids_), "n_perturbations": int(self.n_perturbations),
            "perturbation_timescale_s": float(self.perturbation_timescale_s),
            "single_section_share": float(self.single_section_share),
            "wind_error_rms": float(np.sqrt(np.mean(self.wind_error_**2))),
            "note": self.note_,
            "null": (None if self.null_model is None else
                     {"name": type(self.null_model).__name__,
                      "held_out_loss": float(np.sum(self.null_loss_)),
                      "excess": float(getattr(self, "null_excess_", np.nan)),
                      "se": float(getattr(self, "null_se_", np.nan)),
                      "in_set": self.null_in_set_}),
            "dynamics_shown": bool(getattr(self, "dynamics_shown_", True)),
            "change": dict(getattr(self, "change_", {"tested": False, "detected": False,
                                                     "p_value": float("nan"), "event": ""})),
            "stationary": bool(getattr(self, "stationary_", True)),
            "time_constant_s": float(getattr(self, "time_constant_s_", float("nan"))),
            "event_duration_s": [float(d) for d in getattr(self, "event_duration_s_", [])],
            "short_events": (self.short_events() if hasattr(self, "time_constant_s_") else []),
            "min_time_constants": (None if self.min_time_constants is None else float(self.min_time_constants)),
            "rank_level": (None if self.rank_level is None else float(self.rank_level)),
            "wind_bins": self.wind_bins, "dynamics_by_wind": self._local_evidence(),
            **getattr(self, "settled_evidence_", {}),  # e.g. "wind_smoothing", where the records settled it
        }

    def _local_evidence(self) -> dict | None:
        local = getattr(self, "dynamics_by_wind_", None)
        if local is None:
            return None
        shown, excess, se, n = local
        return {"wind_edges": [float(x) for x in self.wind_edges_], "shown": [bool(x) for x in shown],
                "excess": [float(x) for x in excess], "se": [float(x) for x in se], "n_events": [int(x) for x in n]}

    def evidence_text(self) -> str:
        """One line per candidate: its held-out loss relative to the best, and the set and choice; then the
        null test (campaign-wide and by wind), the change scan and the short events."""
        return evidence_text(self.evidence(), note=self.note_, short_threshold=self._short_threshold())

    def to_dataset(self) -> xr.Dataset:
        """The chosen model's dataset with the evidence as the attribute ``selection_json``."""
        ds = self.model_.to_dataset()
        ds.attrs["selection_json"] = json.dumps(self.evidence(), sort_keys=True)
        return ds

    def save(self, path):
        """Write the chosen model's file with the selection's evidence (atomically); returns the path."""
        from vivbench.io.netcdf import write_netcdf_atomic

        return write_netcdf_atomic(self.to_dataset(), path)


#: The options of :class:`vivbench.models.VaryingCoefficientSINDy` that :func:`varying_selection`
#: chooses from the campaign's evidence by default, each listed simplest first: the yaw covariate
#: (none, or a polynomial in sin^2 of the yaw of degree 1 or 2; degree 2 is scored only where degree 1
#: is chosen over none) and the roughness penalty (the 5-fold cross-validated one, or the least
#: penalty of the leave-one-event-out confidence set, which gives rougher curves).
VARYING_OPTIONS = {"yaw_degree": (0, 1, 2), "penalty_choice": ("cv", "least")}

#: The classes of campaign model a selection of :func:`varying_selection` chooses among by default.
MODEL_CLASSES = ("varying", "pooled")

#: Complexity of the pooled library among the selection's candidates: that of one covariate, so that the
#: one-standard-error rule keeps a yaw-free varying model of the confidence set (a polynomial library in U
#: fitted to few events can predict held-out envelopes as well and extrapolate far worse; development draws,
#: docs/model_selection.md).
POOLED_COMPLEXITY = 1

#: Errors by which winds measured elsewhere on the span are shifted in :meth:`ModelSelection.agreement` (95 %, two-sided).
UNMEASURED_Z = 1.96

#: Options that change what enters the model (a covariate): a candidate's complexity counts their positions in
#: the grid, so the one-standard-error rule prefers leaving them out. The other options (regularisation levels)
#: add no complexity: among the confidence set's models of one structure, the lowest held-out loss decides.
STRUCTURAL_OPTIONS = ("yaw_degree",)

#: Options of the varying model that stay fixed in :func:`varying_selection` unless given: stated priors.
#: The modal section weights are the averaged truth's for a mode seen at the sections (each section's
#: share of the mode's energy); 30 s is the wind's smoothing time scale (a ``wind_smoothing_grid`` given lets the
#: campaign's own cross-validation replace it, :mod:`vivbench.analysis.candidates`; not the default).
VARYING_PRIORS = {"wind_weights": "modal", "wind_smoothing_s": 30.0}


def varying_selection(*, options: dict | None = None, n_folds: int = 5, criterion: str = "output",
                      n_perturbations: int = 2, perturbation_timescale_s: float = 60.0, seed: int = 0,
                      workers: int = 1, scheduler: str | None = None, null: bool = True,
                      change_scan: bool = True, single_section_share: float = SINGLE_SECTION_SHARE,
                      min_time_constants: float | None = LIMIT_TIME_CONSTANTS, rank_level: float | None = RANK_LEVEL,
                      wind_bins: int | None = None, model_classes: Sequence[str] = MODEL_CLASSES,
                      **params) -> ModelSelection:
    """A :class:`ModelSelection` among campaign models: varying-coefficient models over a grid of options and,
    of ``model_classes``, the pooled library.

    Parameters
    ----------
    options : dict of str to sequence, optional
        Parameter name -> candidate values, simplest first (default :data:`VARYING_OPTIONS`); the grid is their
        product and a candidate's complexity is the sum of its values' positions in the :data:`STRUCTURAL_OPTIONS`.
        A parameter given in ``params`` is pinned: it leaves the grid.
    n_folds, criterion, n_perturbations, perturbation_timescale_s, seed, workers, scheduler, single_section_share,
    min_time_constants, rank_level, wind_bins
        Those of :class:`ModelSelection` (``seed`` also the models'; ``min_time_constants`` here
        :data:`LIMIT_TIME_CONSTANTS` by default; ``wind_bins`` None, the campaign-wide null test alone:
        :data:`vivbench.analysis.WIND_BINS` bins cost right flags and mended no broken promise on development
        draws, docs/results/studies/verdict_rules).
    null : bool
        Test the candidates against the quasi-steady map :class:`vivbench.models.QuasiSteadyAmplitude`
        (with the candidates' wind smoothing) before any window is flagged.
    change_scan : bool
        Flag no window when the chosen model's change scan locates a change (:class:`ModelSelection`).
    model_classes : sequence of {"varying", "pooled"}
        The classes of campaign model among the candidates (default :data:`MODEL_CLASSES`): ``"varying"``
        the grid of ``options`` of :class:`vivbench.models.VaryingCoefficientSINDy`; ``"pooled"`` one
        :class:`vivbench.models.PooledSINDy` (the pooled library, no covariate) on the same smoothed wind, of
        complexity :data:`POOLED_COMPLEXITY`: a structure other than the default's, chosen over a yaw-free
        varying candidate only where that one is significantly worse held out.
    **params
        Fixed parameters of every candidate (default :data:`VARYING_PRIORS` where not given).

    Returns
    -------
    ModelSelection, unfitted, whose verdict is the chosen model's own (:func:`vivbench.regimes.model_verdicts`)
    """
    import itertools

    from vivbench.models.quasi_steady import QuasiSteadyAmplitude
    from vivbench.models.varying import VaryingCoefficientSINDy

    classes = tuple(model_classes) if not isinstance(model_classes, str) else (model_classes,)
    if not classes or len(set(classes)) != len(classes) or not set(classes) <= set(MODEL_CLASSES):
        raise InputError(f"model_classes must be distinct names among {', '.join(map(repr, MODEL_CLASSES))}; "
                         f"got {model_classes!r}")
    grid = {k: tuple(v) for k, v in (VARYING_OPTIONS if options is None else options).items() if k not in params}
    for k in [k for k, v in grid.items() if not v]:
        raise InputError(f"option {k!r} has no candidate value")
    fixed = {**{k: v for k, v in VARYING_PRIORS.items() if k not in grid}, **params, "seed": seed}
    names = list(grid)
    candidates = []
    for idx in itertools.product(*(range(len(grid[k])) for k in names)) if "varying" in classes else ():
        chosen = {k: grid[k][i] for k, i in zip(names, idx)}
        label = "-".join(_option_label(k, v) for k, v in chosen.items()) or "varying"
        candidates.append(Candidate(name=label, model=VaryingCoefficientSINDy(**fixed, **chosen),
                                    complexity=int(sum(i for k, i in zip(names, idx) if k in STRUCTURAL_OPTIONS)),
                                    options=({"model_class": "varying"} if len(classes) > 1 else {}) | chosen))
    if "pooled" in classes:  # after the varying candidates: the simplest of those settles the wind smoothing
        from vivbench.models.campaign import PooledSINDy

        own = PooledSINDy().get_params()
        shared = {k: v for k, v in fixed.items() if k in own and k != "wind_smoothing_s"}
        smoothings = grid.get("wind_smoothing_s", (fixed.get("wind_smoothing_s", VARYING_PRIORS["wind_smoothing_s"]),))
        for sigma in smoothings:  # one pooled model per smoothing among the options
            label = "pooled" if len(smoothings) == 1 else f"pooled-{_option_label('wind_smoothing_s', float(sigma))}"
            candidates.append(Candidate(name=label, model=PooledSINDy(**shared, wind_smoothing_s=float(sigma)),
                                        complexity=POOLED_COMPLEXITY,
                                        options={"model_class": "pooled", "wind_smoothing_s": float(sigma)}))
    return ModelSelection(candidates=candidates, n_folds=n_folds, criterion=criterion,
                          n_perturbations=n_perturbations, perturbation_timescale_s=perturbation_timescale_s,
                          tau=fixed.get("tau", DEFAULT_TAU), seed=seed,
                          workers=workers, scheduler=scheduler,
                          null_model=(QuasiSteadyAmplitude(wind_smoothing_s=fixed.get("wind_smoothing_s", 30.0))
                                      if null else None),
                          change_scan=change_scan, single_section_share=single_section_share,
                          min_time_constants=min_time_constants, rank_level=rank_level,
                          wind_bins=(wind_bins if null else None))


def _json_params(model) -> dict:
    """A candidate's parameters (``get_params``) as JSON data (tuples as lists, other objects as text)."""
    own = model.get_params() if callable(getattr(model, "get_params", None)) else {}
    return json.loads(json.dumps(own, sort_keys=True, default=str))


def _option_label(name: str, value) -> str:
    short = {"yaw_degree": "yaw", "penalty_choice": "", "wind_weights": "", "wind_input": "",
             "wind_smoothing_s": "smooth"}
    return f"{short.get(name, name)}{value:g}" if isinstance(value, float) else f"{short.get(name, name)}{value}"

