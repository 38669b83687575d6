"""Candidate terms A_l^i U_l^j and the scaled regression basis (docs/concepts.md (identifiability))."""

from vivbench.library.basis import (
    SCALINGS,
    WindowLibrary,
    window_library,
    library_cond,
    condition_number,
    basis_orders,
    order_contributions_basis,
)

__all__ = [
    "SCALINGS", "WindowLibrary", "window_library", "library_cond", "condition_number", "basis_orders",
    "order_contributions_basis",
]
