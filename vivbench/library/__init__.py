"""Candidate terms A_l^i U_l^j and the scaled regression basis (docs/concepts.md (identifiability)); the cubic
B-spline basis of the models' curves of the wind."""

from vivbench.library.basis import (
    SCALINGS,
    WindowLibrary,
    window_library,
    library_cond,
    condition_number,
    basis_orders,
    order_contributions_basis,
)
from vivbench.library.splines import (DEGREE, bspline_basis, bspline_local, bspline_local_t, difference_penalty,
                                      first_index, uniform_cubic_local_t, uniform_knots)

__all__ = [
    "SCALINGS", "WindowLibrary", "window_library", "library_cond", "condition_number", "basis_orders",
    "order_contributions_basis", "DEGREE", "bspline_basis", "bspline_local", "bspline_local_t", "difference_penalty",
    "first_index", "uniform_cubic_local_t", "uniform_knots",
]
