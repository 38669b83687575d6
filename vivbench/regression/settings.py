"""Settings of the STLSQ threshold path and of AICc selection."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from vivbench.core.errors import InputError

__all__ = ["DEFAULT_THRESHOLDS", "SOLVERS", "StlsqSettings"]

DEFAULT_THRESHOLDS = (0.0,) + tuple(float(x) for x in np.logspace(-3, 2, 21))


SOLVERS = ("auto", "qr", "gram")


@dataclass(frozen=True, kw_only=True)
class StlsqSettings:
    """Settings of the threshold path and of AICc selection.

    Parameters
    ----------
    thresholds : sequence of float
        Strictly increasing, non-negative thresholds on the coefficients of
        the design the path is run on (for :class:`EventWindowSINDy` with
        scaling, standardised coefficients: unit-RMS columns and targets).
    alpha : float
        Ridge parameter added to the diagonal of X^T X (pysindy's ``alpha``
        and its default).
    max_iter : int
        Maximum number of ridge solves per fit, iteration 0 included.
    unbias : bool
        Refit the final support by unregularised least squares (pysindy's
        ``unbias``).
    allow_empty : bool
        Whether the empty model (k = 0) competes in the AICc selection.
    residual_floor : float
        Relative RMS residual below which a fit counts as exact (see module
        docstring); 0 disables the floor.
    refit_rcond : float or None
        The unbiased refit discards singular values of X_S below
        ``refit_rcond`` times the largest (minimum-norm solution), as
        pysindy's refit does: scikit-learn's ``LinearRegression`` (>= 1.7)
        calls ``scipy.linalg.lstsq`` with ``cond=tol = 1e-6``. None: plain
        least squares (older scikit-learn behaves so up to eps).
    solver : {"auto", "qr", "gram"}
        How STLSQ iterations are solved (final refits always use QR):
        ``"auto"`` by Cholesky where the ridge guarantees accuracy (see the
        module docstring), else QR; ``"qr"`` always QR; ``"gram"`` always
        Cholesky of the normal equations, pysindy's default arithmetic, which
        loses all accuracy once cond(X_S)^2 exceeds 1/eps.
    """

    thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS
    alpha: float = 0.05
    max_iter: int = 20
    unbias: bool = True
    allow_empty: bool = False
    residual_floor: float = 1e-8
    refit_rcond: float | None = 1e-6
    solver: str = "auto"

    def __post_init__(self) -> None:
        th = np.asarray(self.thresholds, dtype=float).ravel()
        if th.size == 0 or not np.all(np.isfinite(th)) or np.any(th < 0):
            raise InputError(f"thresholds must be a non-empty sequence of finite values >= 0; got {self.thresholds!r}")
        if np.any(np.diff(th) <= 0):
            raise InputError("thresholds must be strictly increasing")
        object.__setattr__(self, "thresholds", tuple(float(x) for x in th))
        if not (np.isfinite(self.alpha) and self.alpha >= 0):
            raise InputError(f"alpha must be finite and >= 0; got {self.alpha}")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, (int, np.integer)) or self.max_iter < 1:
            raise InputError(f"max_iter must be an integer >= 1; got {self.max_iter!r}")
        if not (np.isfinite(self.residual_floor) and 0 <= self.residual_floor < 1):
            raise InputError(f"residual_floor must lie in [0, 1); got {self.residual_floor}")
        if self.refit_rcond is not None and not (np.isfinite(self.refit_rcond) and 0 <= self.refit_rcond < 1):
            raise InputError(f"refit_rcond must be None or lie in [0, 1); got {self.refit_rcond}")
        if self.solver not in SOLVERS:
            raise InputError(f"solver must be one of {SOLVERS}; got {self.solver!r}")

