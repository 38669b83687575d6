"""Any ``pysindy.SINDy`` as a model of the protocol (docs/methods.md): per window or over a whole campaign.

:class:`PySINDyWindows` fits one copy of a user's ``pysindy.SINDy`` per
sliding window of every record (the paper's time-varying SINDy, with any
library, optimiser or differentiation); :class:`PySINDyCampaign` fits one
copy to all records at once (multiple trajectories, the wind as control
input). :class:`PySINDyCP` is the pysindy reference of a campaign model whose
coefficients are functions of the wind: a ``ParameterizedLibrary`` (the
feature library in A tensored with a parameter library in U, what
``SINDyCP`` did before pysindy 2 dropped that class).

The state is x = A (one column per section, names ``A1..AS``), the control
input u = U (``U1..US``). With ``standardize=True`` (the default: raw powers
of U are collinear, condition numbers up to 1e17) pysindy sees
x = A / a_s and u = (U - u_c) / u_s, with a_s the RMS of A and u_c, u_s the
mean and standard deviation of U over the fitted samples. Scaling A by a
constant keeps the power of A of every term, and shifting U keeps it too, so
the orders below are those of the physical A; the fitted coefficients and
the feature names printed by ``equations()`` are in the scaled variables.

Order contributions (``order_contributions``) split the fitted right-hand
side by power of A: each fitted feature name (pysindy's ``get_feature_names``
with the names above, e.g. ``"A1^2 U1"`` or ``"U1 A1"``) is read as a product
of factors ``name`` or ``name^k``; the power of A of the term is the sum of
the exponents of the A factors (0 for ``"1"`` and pure-U terms). A term that
is not such a monomial (``sin(A1)``, ``A1/U1``, a weak-form or PDE term), or
whose power of A exceeds 3, has no order of docs/concepts.md (regimes). With
``other_terms="refuse"`` (default) fitting raises ``ValueError`` naming the
first such term with a nonzero coefficient (terms whose coefficients are all
zero are ignored); with ``"aside"`` those terms are kept out of
``order_contributions`` (so the four orders no longer sum to ``predict``,
which still includes them) and their share of the fitted right-hand side is
reported in ``other_share_``.

Neither adapter gives an identifiability verdict: scored by
:func:`vivbench.validate.score_method` they get coverage 0, their regimes
scored on all windows.

``save`` and ``load`` (:mod:`vivbench.io.pysindy_model`) keep what a model needs to predict: its
coefficients, the names of its library's terms and the library's settings (of a user's ``sindy``: the
classes and plain parameters of its library, optimiser and differentiation); ``load`` rebuilds the library
and refuses a file whose settings do not give its terms.
"""

from __future__ import annotations

import copy
import json
import re
from collections.abc import Sequence
from types import SimpleNamespace

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.io.model_file import ModelFileError
from vivbench.io.pysindy_model import pysindy_model_dataset, read_pysindy_model, write_pysindy_model
from vivbench.models.campaign import amplitude_ratios
from vivbench.models.integrate import StopRule, rk4
from vivbench.models.protocol import ModelBase, fit_records, section_names
from vivbench.models.window_model import nearest_window
from vivbench.preprocess.runs import mask_runs
from vivbench.preprocess.windows import window_bounds

__all__ = ["PySINDyWindows", "PySINDyCampaign", "PySINDyCP", "term_orders", "OTHER_TERMS"]

#: What to do with fitted terms that are not monomials in A of order <= 3.
OTHER_TERMS = ("refuse", "aside")

_FACTOR = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?:\^(\d+))?$")


def term_orders(feature_names: Sequence[str], state_names: Sequence[str], input_names: Sequence[str]) -> np.ndarray:
    """Power of A of each library term, read from its name; -1 where the term has no order.

    Parameters
    ----------
    feature_names : sequence of str
        pysindy feature names: space-separated factors ``name`` or ``name^k``, ``"1"`` for a constant.
    state_names, input_names : sequence of str
        Names of the state (A) and of the control input (U) columns.

    Returns
    -------
    ndarray of int, shape (p,)
        0..3 for monomials in A (times any monomial in U); -1 for any other
        term (a factor that is not a plain power of a known name, or a power
        of A above 3).
    """
    state, inputs = set(state_names), set(input_names)
    out = np.empty(len(feature_names), dtype=int)
    for j, name in enumerate(feature_names):
        order = 0
        for factor in str(name).split():
            if factor == "1":
                continue
            m = _FACTOR.match(factor)
            if m is None or m.group(1) not in state | inputs:
                order = -1
                break
            if m.group(1) in state:
                order += int(m.group(2) or 1)
        out[j] = order if 0 <= order <= 3 else -1
    return out


def term_a_exponents(feature_names: Sequence[str], state_names: Sequence[str],
                     input_names: Sequence[str]) -> np.ndarray:
    """Exponent of each state (A) variable in each term, shape (p, S); NaN rows for terms that are not monomials."""
    index = {n: k for k, n in enumerate(state_names)}
    inputs = set(input_names)
    out = np.zeros((len(feature_names), len(state_names)))
    for j, name in enumerate(feature_names):
        for factor in str(name).split():
            if factor == "1":
                continue
            m = _FACTOR.match(factor)
            if m is None or (m.group(1) not in index and m.group(1) not in inputs):
                out[j] = np.nan
                break
            if m.group(1) in index:
                out[j, index[m.group(1)]] += int(m.group(2) or 1)
    return out


def _finite_runs(t: np.ndarray, ok: np.ndarray, min_samples: int) -> list[slice]:
    """Maximal runs of consecutive samples where ``ok`` holds, ending at gaps in time
    (:func:`vivbench.preprocess.mask_runs`), with at least ``min_samples`` samples."""
    return [run for run in mask_runs(ok, t) if run.stop - run.start >= min_samples]


def _default_sindy():
    import pysindy as ps

    return ps.SINDy(feature_library=ps.PolynomialLibrary(degree=3), optimizer=ps.STLSQ(threshold=1e-3))


#: The parts of a user's ``pysindy.SINDy`` that a model file keeps (its constructor's arguments).
_SINDY_PARTS = ("feature_library", "optimizer", "differentiation_method")


def _part_settings(obj, part: str) -> dict:
    """``{"class": name, "params": ...}`` of a pysindy object whose class is ``pysindy.<name>`` and whose
    parameters are plain JSON values; ValueError otherwise (the file could not rebuild it)."""
    import pysindy as ps

    name = type(obj).__name__
    try:
        params = obj.get_params(deep=False)
        plain = getattr(ps, name, None) is type(obj) and json.loads(json.dumps(params)) == params
    except (AttributeError, TypeError, ValueError):
        plain = False
    if not plain:
        raise ValueError(f"cannot save this model: its sindy's {part} ({name}) is not a pysindy class with plain "
                         "parameters, so a file could not rebuild it (a PolynomialLibrary and STLSQ can be saved)")
    return {"class": name, "params": params}


def _sindy_from_settings(settings: dict):
    """The ``pysindy.SINDy`` of :func:`_part_settings`' entries (unfitted)."""
    import pysindy as ps

    return ps.SINDy(**{part: getattr(ps, s["class"])(**s["params"]) for part, s in settings.items()})


class _PySINDyBase(ModelBase):
    """What both adapters share: scaling, the inputs pysindy sees, fitted term orders."""

    _fitted_attribute = "coef_"

    def __repr__(self) -> str:
        # sklearn's repr of some pysindy libraries fails (ParameterizedLibrary in pysindy 2.1): name the types only.
        sindy = self.sindy
        lib = type(getattr(sindy, "feature_library", None)).__name__
        opt = type(getattr(sindy, "optimizer", None)).__name__
        others = {k: v for k, v in self.get_params().items() if k != "sindy"}
        return (f"{type(self).__name__}(sindy=SINDy({lib}, {opt}), "
                + ", ".join(f"{k}={v!r}" for k, v in others.items()) + ")")

    def _check_params(self) -> None:
        if self.other_terms not in OTHER_TERMS:
            raise ValueError(f"other_terms must be one of {', '.join(OTHER_TERMS)}; got {self.other_terms!r}")
        if self.sindy is not None and not hasattr(self.sindy, "fit"):
            raise TypeError(f"sindy must be a pysindy.SINDy (an object with fit); got {type(self.sindy).__name__}")
        if type(getattr(self.sindy, "feature_library", None)).__name__ == "WeakPDELibrary":
            raise InputError("pysindy's WeakPDELibrary holds one time grid (spatiotemporal_grid) for all data, but "
                             "records and their runs of valid samples have grids of their own; use "
                             "vivbench.models.PySINDyWeak, which builds the weak form per run (docs/methods.md)")

    def _new_sindy(self):
        # deepcopy, not sklearn.clone: ParameterizedLibrary cannot be cloned in pysindy 2.1.
        return copy.deepcopy(self.sindy if self.sindy is not None else _default_sindy())

    def _set_scales(self, records: list[Record]) -> None:
        S = records[0].n_sections
        A = np.concatenate([r.A for r in records])
        U = np.concatenate([r.U for r in records])
        if self.standardize:
            a = float(np.sqrt(np.nanmean(A**2)))
            self.a_scale_ = a if np.isfinite(a) and a > 0 else 1.0
            self.u_center_ = float(np.nanmean(U))
            s = float(np.nanstd(U))
            self.u_scale_ = s if np.isfinite(s) and s > 0 else 1.0
        else:
            self.a_scale_, self.u_center_, self.u_scale_ = 1.0, 0.0, 1.0
        self.n_sections_ = S
        self.state_names_ = [f"A{k + 1}" for k in range(S)]
        self.input_names_ = [f"U{k + 1}" for k in range(S)]

    def _inputs(self, A: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return A / self.a_scale_, (U - self.u_center_) / self.u_scale_

    def _records(self, records) -> list[Record]:
        return fit_records(records, need_dA=self.use_record_derivative, why="use_record_derivative=True needs it")

    def _pieces(self, records: list[Record]) -> list[tuple]:
        """(t, A, U, dA) of every run of at least ``min_samples`` valid samples of every record."""
        out = []
        for rec in records:
            for run in _finite_runs(rec.t, rec.valid(need_dA=self.use_record_derivative), self.min_samples):
                out.append((rec.t[run], rec.A[run], rec.U[run], None if rec.dA is None else rec.dA[run]))
        return out

    def _fit_sindy(self, pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]):
        """Fit a fresh copy on (t, A, U, dA) pieces (one trajectory each); returns it."""
        model = self._new_sindy()
        xs, us, dxs, ts = [], [], [], []
        for t, A, U, dA in pieces:
            x, u = self._inputs(A, U)
            xs.append(x)
            us.append(u)
            ts.append(t)
            if self.use_record_derivative:
                dxs.append(dA / self.a_scale_)
        names = self.state_names_ + self.input_names_
        if self.use_record_derivative:
            model.fit(xs, t=ts, x_dot=dxs, u=us, feature_names=names)
        else:
            model.fit(xs, t=ts, u=us, feature_names=names)
        return model

    def _term_info(self, model) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Feature names, the fitted coefficients (S, p) on the scaled variables and the term orders."""
        names = [str(n) for n in model.get_feature_names()]
        coef = np.asarray(model.coefficients(), dtype=float)
        orders = term_orders(names, self.state_names_, self.input_names_)
        other = (orders < 0) & np.any(coef != 0, axis=0)
        if other.any() and self.other_terms == "refuse":
            raise ValueError(f"the fitted term {names[int(np.flatnonzero(other)[0])]!r} is not a monomial in A of "
                             "order <= 3, so its dynamics have no order (docs/concepts.md (regimes)); use a library of monomials in "
                             "A and U, or other_terms='aside' to keep such terms out of order_contributions")
        return names, coef, orders

    def _theta(self, model, record: Record) -> tuple[np.ndarray, np.ndarray]:
        """Library matrix (n, p) of the record's samples (NaN where A or U is missing) and the valid mask."""
        ok = record.valid()
        x, u = self._inputs(record.A[ok], record.U[ok])
        p = len(self.feature_names_)
        theta = np.full((record.n_samples, p), np.nan)
        if ok.any():
            theta[ok] = np.asarray(model.feature_library.transform(np.hstack([x, u])), dtype=float)
        return theta, ok

    # ------------------------------------------------------------------ files (vivbench.io.pysindy_model)

    def _prediction_library(self):
        """A fresh (unfitted) copy of the feature library whose terms the coefficients multiply."""
        return self._new_sindy().feature_library

    def save(self, path):
        """Write what the fitted model needs to predict (:mod:`vivbench.io.pysindy_model`) atomically; returns the path.

        The coefficients, the library's term names and its settings (a user's ``sindy``: the classes and
        parameters of its library, optimiser and differentiation) are written, not the pysindy objects.

        Raises
        ------
        ValueError
            The model's ``sindy`` holds a part that is not a pysindy class with plain parameters.
        """
        self._check_fitted()
        params = self.get_params()
        given = params.pop("sindy", None)  # a user's SINDy (the variants build their own from their parameters)
        settings = None if given is None else {part: _part_settings(getattr(given, part), part) for part in _SINDY_PARTS}
        ds = pysindy_model_dataset(type(self).__name__, vars(self), params_json=json.dumps(params, sort_keys=True),
                                   sindy_json=json.dumps(settings, sort_keys=True))
        return write_pysindy_model(ds, path)

    @classmethod
    def load(cls, path):
        """A fitted model from a file written by :meth:`save`: its library rebuilt, its predictions the saved model's.

        Raises
        ------
        InputError
            One line naming the file: not such a file, or a library rebuilt from the file's settings whose
            terms are not the file's.
        """
        params, settings, fitted = read_pysindy_model(path, model_name=cls.__name__)
        if settings is not None:
            params["sindy"] = _sindy_from_settings(settings)
        model = cls(**params)
        for name, value in fitted.items():
            setattr(model, name, value)
        S = model.n_sections_
        model.state_names_ = [f"A{k + 1}" for k in range(S)]
        model.input_names_ = [f"U{k + 1}" for k in range(S)]
        library = model._prediction_library()
        library.fit(np.zeros((1, 2 * S)))
        names = [str(n) for n in library.get_feature_names(model.state_names_ + model.input_names_)]
        if names != model.feature_names_:
            raise ModelFileError(f"{path}: the library rebuilt from the file's settings has the terms {names}, "
                                 f"not the file's {model.feature_names_}")
        model.term_orders_ = term_orders(names, model.state_names_, model.input_names_)
        model.a_exponents_ = term_a_exponents(names, model.state_names_, model.input_names_)
        holder = SimpleNamespace(feature_library=library, get_feature_names=lambda: list(names),
                                 coefficients=lambda: model.coef_)
        model._set_library(holder)
        return model

    def _set_library(self, holder) -> None:
        """Keep a loaded model's library where its predictions look for it."""
        self.sindy_ = holder

    def equations(self, precision: int = 3) -> list[str]:
        """pysindy-like equations of the fitted model(s), in the scaled variables (see the module docstring)."""
        from vivbench.models.protocol import format_equations

        coef = self.coef_ if self.coef_.ndim == 2 else np.nanmedian(self.coef_, axis=0)
        return format_equations(coef, self.feature_names_, [f"d{n}/dt" for n in self.state_names_], precision)


class PySINDyCampaign(_PySINDyBase):
    """One ``pysindy.SINDy`` fitted to all records of a campaign (a campaign-level method).

    Parameters
    ----------
    sindy : pysindy.SINDy, optional
        Any library, optimiser and differentiation; copied before fitting.
        Default: ``SINDy(PolynomialLibrary(degree=3), STLSQ(threshold=1e-3))``.
    standardize : bool
        Fit on x = A / a_s, u = (U - u_c) / u_s (module docstring); False: physical A and U.
    use_record_derivative : bool
        True (default): pysindy gets the records' dA as ``x_dot``; False: pysindy
        differentiates A itself with the SINDy's differentiation method.
    other_terms : {"refuse", "aside"}
        Terms that are not monomials in A of order <= 3 (module docstring).
    min_samples : int
        Runs of consecutive valid samples shorter than this are not fitted.

    Attributes
    ----------
    sindy_ : the fitted pysindy.SINDy
    coef_ : ndarray, shape (S, p), on the scaled variables
    feature_names_ : list of str
    term_orders_ : ndarray of int, shape (p,)
        Power of A of each term (-1: no order).
    a_scale_, u_center_, u_scale_ : float (m, m/s, m/s)
    n_sections_, n_trajectories_ : int
    other_share_ : float
        RMS of the terms without an order relative to the RMS of the whole fitted right-hand side.
    amplitude_ratios_ : ndarray, shape (S, S)
        Median A_l / A_k of the fitted data (:func:`vivbench.models.amplitude_ratios`), for ``curves``.
    """

    def __init__(self, *, sindy=None, standardize: bool = True, use_record_derivative: bool = True,
                 other_terms: str = "refuse", min_samples: int = 10):
        self.sindy = sindy
        self.standardize = standardize
        self.use_record_derivative = use_record_derivative
        self.other_terms = other_terms
        self.min_samples = min_samples

    def fit(self, records: Sequence[Record]) -> "PySINDyCampaign":
        """Fit one SINDy to every run of valid samples of every record (multiple trajectories).

        Returns
        -------
        self
        """
        self._check_params()
        records = self._records(records)
        self._set_scales(records)
        pieces = self._pieces(records)
        if not pieces:
            raise ValueError(f"no run of at least {self.min_samples} valid samples to fit")
        model = self._fit_sindy(pieces)
        names, coef, orders = self._term_info(model)
        self.sindy_ = model
        self.feature_names_ = names
        self.term_orders_ = orders
        self.a_exponents_ = term_a_exponents(names, self.state_names_, self.input_names_)
        self.n_trajectories_ = len(pieces)
        self.coef_ = coef
        self.other_share_ = self._other_share(records)
        self.amplitude_ratios_ = amplitude_ratios(np.concatenate([r.A for r in records]))
        return self

    def _other_share(self, records) -> float:
        if not np.any(self.term_orders_ < 0):
            return 0.0
        tot, oth = 0.0, 0.0
        for rec in records:
            theta, ok = self._theta(self.sindy_, rec)
            f = theta[ok] @ self.coef_.T
            g = theta[ok][:, self.term_orders_ < 0] @ self.coef_[:, self.term_orders_ < 0].T
            tot += float(np.sum(f**2))
            oth += float(np.sum(g**2))
        return float(np.sqrt(oth / tot)) if tot > 0 else 0.0

    def order_contributions(self, record: Record) -> np.ndarray:
        """r_0..r_3 of dA/dt, shape (n_samples, n_sections, 4), m/s (NaN where A or U is missing)."""
        record = self._check_record(record)
        theta, _ok = self._theta(self.sindy_, record)
        r = np.empty(record.A.shape + (4,))
        for i in range(4):
            cols = self.term_orders_ == i
            r[..., i] = theta[:, cols] @ self.coef_[:, cols].T
        return r * self.a_scale_

    def predict(self, record: Record) -> np.ndarray:
        """dA/dt of the fitted SINDy (all its terms), shape (n_samples, n_sections), m/s."""
        record = self._check_record(record)
        theta, _ok = self._theta(self.sindy_, record)
        return theta @ self.coef_.T * self.a_scale_

    def simulate(self, record: Record, t0: float | None = None, t1: float | None = None, A0=None,
                 bound_factor: float = 3.0):
        """Integrate the fitted model with the record's wind (classical RK4 on the record's time grid).

        The right-hand side of a library of monomials in A is sum_j xi_kj g_j(U) prod_l A_l^p_lj:
        the wind parts g_j are evaluated once on the samples and midpoints (U linear between
        samples), so each step costs a few small array operations.

        Parameters
        ----------
        record : Record
        t0, t1 : float, s, optional
            Span, snapped to the record's samples (default: the whole record; U must be finite on it).
        A0 : array_like, shape (S,), m, optional
            Initial amplitudes (default: the record's A at t0).
        bound_factor : float
            The run stops where an amplitude leaves [0, bound_factor x the largest measured
            amplitude of the span] (as :func:`vivbench.models.simulate_identified`).

        Returns
        -------
        vivbench.models.Simulation

        Raises
        ------
        ValueError
            When fitted terms without an order were set aside (``other_terms="aside"``): their
            dependence on A is not a monomial, which this integrator needs.
        """
        from vivbench.models.simulate import Simulation, nmse

        record = self._check_record(record)
        if np.any((self.term_orders_ < 0) & np.any(self.coef_ != 0, axis=0)):
            raise ValueError("simulate needs a right-hand side of monomials in A; this model has terms set aside")
        t = record.t
        i0 = 0 if t0 is None else int(np.argmin(np.abs(t - float(t0))))
        i1 = t.size - 1 if t1 is None else int(np.argmin(np.abs(t - float(t1))))
        tt, A_meas, U = t[i0:i1 + 1], record.A[i0:i1 + 1], record.U[i0:i1 + 1]
        if tt.size < 2 or not np.all(np.isfinite(U)):
            raise ValueError(f"record {record.event_id!r}: the span needs >= 2 samples and finite U")
        S = self.n_sections_
        keep = np.any(self.coef_ != 0, axis=0)
        P = self.a_exponents_[keep]  # (p', S)
        coef = self.coef_[:, keep] * self.a_scale_  # dA/dt in m/s per unit scaled feature

        def wind_part(Ux):
            # theta at x = 1 (A = a_s) is the wind part of every monomial term
            rec = Record(event_id=record.event_id, t=np.arange(Ux.shape[0], dtype=float),
                         A=np.full(Ux.shape, self.a_scale_), U=Ux)
            return self._theta(self.sindy_, rec)[0][:, keep]

        g = wind_part(U)
        g_mid = wind_part(0.5 * (U[1:] + U[:-1]))
        x = (np.asarray(A_meas[0] if A0 is None else A0, dtype=float) / self.a_scale_).reshape(S)
        top = bound_factor * np.nanmax(A_meas)
        g_stage = (g, g_mid, g)  # the wind parts at a step's start, midpoint and end (index n + 1)

        def f(xv, n, stage):
            gv = g_stage[stage][n + (stage == 2)]
            return coef @ (gv * np.prod(xv[None, :] ** P, axis=1)) / self.a_scale_

        run = rk4(f, x, tt, stop=StopRule(upper=top, lower=0.0, scale=self.a_scale_))
        out = run.x * self.a_scale_
        stop = None if run.stop < 0 else int(run.stop)
        covered = 1.0 if stop is None else stop / (tt.size - 1)
        return Simulation(t=tt, A_sim=out, A_meas=A_meas, stopped_at=None if stop is None else float(tt[stop]),
                          reason=None if stop is None else "amplitude left the data's range", nmse=nmse(out, A_meas),
                          covered=float(covered), windows=np.zeros(0, dtype=int))

    def curves(self, wind) -> "xr.Dataset":
        """Coefficient curves a_ki(U) of docs/concepts.md (coefficient curves) (no bands: a single fit has no replicates).

        With every section at the wind U and A_l = rho_kl A_k (``amplitude_ratios_``, the median
        ratios of the fitted data; a pair without data counts as rho = 0), a term of power i in A
        is a_ki(U) A_k^i, so a_ki(U) is the order-i contribution to dA_k/dt at A_k = 1 m.

        Parameters
        ----------
        wind : array_like, shape (n_wind,), m/s

        Returns
        -------
        xarray.Dataset
            ``curves`` (equation, order, wind) in m^(1-i)/s, ``curves_lower`` and ``curves_upper``
            NaN; coordinates ``equation``, ``order``, ``wind`` (m/s).
        """
        import xarray as xr

        self._check_fitted()
        wind = np.atleast_1d(np.asarray(wind, dtype=float))
        if wind.ndim != 1 or wind.size < 1 or not np.all(np.isfinite(wind)):
            raise ValueError("wind must be a 1-D array of finite speeds in m/s")
        S = self.n_sections_
        rho = np.nan_to_num(self.amplitude_ratios_, nan=0.0)
        out = np.empty((S, 4, wind.size))
        for k in range(S):
            A = np.repeat(rho[k][None], wind.size, axis=0)
            rec = Record(event_id="curves", t=np.arange(wind.size, dtype=float), A=A,
                         U=np.repeat(wind[:, None], S, axis=1))
            out[k] = self.order_contributions(rec)[:, k, :].T
        dims = ("equation", "order", "wind")
        units = {"units": "m^(1-order) s-1"}
        return xr.Dataset({"curves": (dims, out, units), "curves_lower": (dims, np.full_like(out, np.nan), units),
                           "curves_upper": (dims, np.full_like(out, np.nan), units)},
                          coords={"equation": section_names(S), "order": np.arange(4),
                                  "wind": ("wind", wind, {"units": "m/s"})},
                          attrs={"model": type(self).__name__})


class PySINDyWindows(_PySINDyBase):
    """One ``pysindy.SINDy`` fitted per sliding window of every record (time-varying SINDy, the paper's method).

    Parameters
    ----------
    sindy, standardize, use_record_derivative, other_terms, min_samples
        As :class:`PySINDyCampaign` (``min_samples``: fewest valid samples of a fitted window).
    window, step : float, s
        Sliding windows over each run of valid samples (:func:`vivbench.preprocess.windows.window_bounds`).

    Attributes
    ----------
    coef_ : ndarray, shape (W, S, p), on the scaled variables, every window of every event
    window_start_, window_end_ : ndarray, shape (W,), s
    window_event_ : ndarray of int, shape (W,), index into ``event_ids_``
    event_ids_ : list of str
    feature_names_, term_orders_, a_scale_, u_center_, u_scale_, n_sections_ : as :class:`PySINDyCampaign`

    Notes
    -----
    Evaluated on a record, the model at a time is that of the event's window
    whose centre is nearest (:func:`vivbench.models.nearest_window`, as
    :class:`vivbench.models.WindowSINDy`); only the events fitted can be
    evaluated.
    """

    def __init__(self, *, sindy=None, window: float = 50.0, step: float = 25.0, standardize: bool = True,
                 use_record_derivative: bool = True, other_terms: str = "refuse", min_samples: int = 10):
        self.sindy = sindy
        self.window = window
        self.step = step
        self.standardize = standardize
        self.use_record_derivative = use_record_derivative
        self.other_terms = other_terms
        self.min_samples = min_samples

    def fit(self, records: Sequence[Record]) -> "PySINDyWindows":
        """Fit one SINDy per window of every record.

        Returns
        -------
        self
        """
        self._check_params()
        records = self._records(records)
        ids = [r.event_id for r in records]
        dup = sorted({e for e in ids if ids.count(e) > 1})
        if dup:
            raise ValueError(f"event ids must be distinct; repeated: {', '.join(dup)}")
        self._set_scales(records)
        coefs, starts, ends, events, names, orders = [], [], [], [], None, None
        for k, rec in enumerate(records):
            ok = rec.valid(need_dA=self.use_record_derivative)
            for run in _finite_runs(rec.t, ok, max(self.min_samples, 2)):
                t = rec.t[run]
                if t[-1] - t[0] < self.window * (1 - 1e-9) - float(np.median(np.diff(t))):
                    continue
                start, end, first, stop = window_bounds(t, self.window, self.step)
                for s, e, a, b in zip(start, end, first, stop):
                    sl = slice(run.start + a, run.start + b)
                    if b - a < self.min_samples:
                        continue
                    model = self._fit_sindy([(rec.t[sl], rec.A[sl], rec.U[sl],
                                              None if rec.dA is None else rec.dA[sl])])
                    n, c, o = self._term_info(model)
                    if names is None:
                        names, orders, self._library = n, o, model
                    elif n != names:
                        raise ValueError("the SINDy's library gave different terms in different windows; "
                                         "window models need one library")
                    coefs.append(c)
                    starts.append(s)
                    ends.append(e)
                    events.append(k)
        if not coefs:
            raise ValueError(f"no run of valid samples is as long as one window ({self.window:g} s)")
        self.event_ids_ = ids
        self.feature_names_ = names
        self.term_orders_ = orders
        self.coef_ = np.stack(coefs)
        self.window_start_ = np.asarray(starts, dtype=float)
        self.window_end_ = np.asarray(ends, dtype=float)
        self.window_event_ = np.asarray(events, dtype=int)
        return self

    def _set_library(self, holder) -> None:
        self._library = holder

    def coef_at(self, record: Record) -> np.ndarray:
        """Coefficients in force at each sample (nearest window centre), shape (n_samples, S, p)."""
        record = self._check_record(record)
        if record.event_id not in self.event_ids_:
            raise KeyError(f"event {record.event_id!r} was not fitted; window models hold only the events they saw")
        w = np.flatnonzero(self.window_event_ == self.event_ids_.index(record.event_id))
        if w.size == 0:
            return np.full((record.n_samples,) + self.coef_.shape[1:], np.nan)
        pick = nearest_window(self.window_start_[w], self.window_end_[w], np.ones(w.size, dtype=bool), record.t)
        return self.coef_[w][pick]

    def order_contributions(self, record: Record) -> np.ndarray:
        """r_0..r_3 of dA/dt with the window in force at each sample, shape (n_samples, S, 4), m/s."""
        record = self._check_record(record)
        coef = self.coef_at(record)
        theta, _ok = self._theta(self._library, record)
        r = np.empty(record.A.shape + (4,))
        for i in range(4):
            cols = self.term_orders_ == i
            r[..., i] = np.einsum("nc,nkc->nk", theta[:, cols], coef[:, :, cols])
        return r * self.a_scale_

    def predict(self, record: Record) -> np.ndarray:
        """dA/dt with the window in force at each sample (all terms), shape (n_samples, S), m/s."""
        record = self._check_record(record)
        theta, _ok = self._theta(self._library, record)
        return np.einsum("nc,nkc->nk", theta, self.coef_at(record)) * self.a_scale_


class PySINDyCP(PySINDyCampaign):
    """The SINDyCP reference: coefficients as polynomials in U through pysindy's ``ParameterizedLibrary``.

    The feature library is ``PolynomialLibrary(a_degree, include_interaction=False)`` in A (terms
    1, A_k, ..., A_k^a_degree), the parameter library ``PolynomialLibrary(u_degree,
    include_interaction=False)`` in U (1, U_k, ..., U_k^u_degree); the model's terms are their
    products (every equation may use every section's terms, like the library of docs/concepts.md (identifiability) but
    with all sections' U powers on every A term), fitted with ``STLSQ(threshold)`` on the
    standardised variables to all records at once. pysindy 2 has no ``SINDyCP`` class any more:
    a ``SINDy`` with a ``ParameterizedLibrary`` and the parameters as control input is its
    replacement.

    Parameters
    ----------
    u_degree, a_degree : int
        Degrees in U and in A (a_degree <= 3: the orders of docs/concepts.md (regimes)).
    threshold : float
        STLSQ threshold on the standardised coefficients (dx/dt in 1/s with x = A / a_s).
    standardize, use_record_derivative, other_terms, min_samples
        As :class:`PySINDyCampaign`.
    """

    def __init__(self, *, u_degree: int = 5, a_degree: int = 3, threshold: float = 1e-3, standardize: bool = True,
                 use_record_derivative: bool = True, other_terms: str = "refuse", min_samples: int = 10):
        self.u_degree = u_degree
        self.a_degree = a_degree
        self.threshold = threshold
        self.standardize = standardize
        self.use_record_derivative = use_record_derivative
        self.other_terms = other_terms
        self.min_samples = min_samples

    @property
    def sindy(self):
        """The (unfitted) SINDy for the fitted number of sections (3 before fitting)."""
        return self._build(getattr(self, "n_sections_", 3))

    def _build(self, n_sections: int):
        import pysindy as ps

        if not 1 <= self.a_degree <= 3:
            raise ValueError(f"a_degree must be 1..3 (the orders of docs/concepts.md (regimes)); got {self.a_degree}")
        lib = ps.ParameterizedLibrary(
            parameter_library=ps.PolynomialLibrary(degree=self.u_degree, include_interaction=False),
            feature_library=ps.PolynomialLibrary(degree=self.a_degree, include_interaction=False),
            num_parameters=n_sections, num_features=n_sections)
        return ps.SINDy(feature_library=lib, optimizer=ps.STLSQ(threshold=self.threshold))

    def _new_sindy(self):
        return self._build(self.n_sections_)
