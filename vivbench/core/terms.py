"""The candidate terms A_l^i U_l^j shared by the truth and the identification.

One section's library has the 23 monomials A^i U^j with i = 0..3, j = 0..5 and
(i, j) != (0, 0); the full library concatenates the sections (69 columns for
three). The order is by section, then by the power of A, then by the power of
U, so that a coefficient vector reshaped to (n_sections, 4, 6) lines up with
the regimes of the paper's Table 1 (the order of A is the regime's signature).
Names follow pysindy's convention for products of powers ("A1^2 U1^3").
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "A_POWERS",
    "U_POWERS",
    "SECTIONS",
    "reference_section",
    "section_exponents",
    "feature_exponents",
    "feature_names",
    "evaluate_library",
]

A_POWERS = (0, 1, 2, 3)
U_POWERS = (0, 1, 2, 3, 4, 5)
SECTIONS = ("S1", "S2", "S3")


def reference_section(n_sections: int) -> int:
    """Index of the section that single-section figures and headline numbers use.

    The middle section (the lower of the two middle ones for an even count):
    the mode's antinode on a symmetric bridge, S2 of the default three, S1 of
    one or two, S2 of four. Any number of sections >= 1 is allowed.

    Parameters
    ----------
    n_sections : int
        Number of instrumented sections, >= 1.

    Returns
    -------
    int
        0-based index, ``(n_sections - 1) // 2``.
    """
    n = int(n_sections)
    if n < 1:
        raise ValueError(f"need at least one section; got {n_sections}")
    return (n - 1) // 2


def section_exponents() -> np.ndarray:
    """Exponents (i, j) of one section's 23 terms, shape (23, 2), in library order."""
    return np.array([(i, j) for i in A_POWERS for j in U_POWERS if (i, j) != (0, 0)], dtype=int)


def feature_exponents(n_sections: int = 3) -> np.ndarray:
    """Rows (section, i, j) of the full library, shape (23 * n_sections, 3)."""
    ex = section_exponents()
    return np.array([(s, i, j) for s in range(n_sections) for i, j in ex], dtype=int)


def _monomial(a: str, u: str, i: int, j: int) -> str:
    parts = []
    if i:
        parts.append(a if i == 1 else f"{a}^{i}")
    if j:
        parts.append(u if j == 1 else f"{u}^{j}")
    return " ".join(parts)


def feature_names(n_sections: int = 3) -> list[str]:
    """pysindy-style names of the full library, e.g. ``"A2^3 U2^5"``."""
    return [
        _monomial(f"A{s + 1}", f"U{s + 1}", i, j) for s, i, j in feature_exponents(n_sections)
    ]


def evaluate_library(A: np.ndarray, U: np.ndarray) -> np.ndarray:
    """Evaluate the raw (unscaled) library.

    Parameters
    ----------
    A : ndarray, shape (n_samples, n_sections), m
        Vibration amplitudes.
    U : ndarray, shape (n_samples, n_sections), m/s
        Mean wind speeds perpendicular to the span.

    Returns
    -------
    Theta : ndarray, shape (n_samples, 23 * n_sections)
    """
    A = np.asarray(A, dtype=float)
    U = np.asarray(U, dtype=float)
    if A.shape != U.shape or A.ndim != 2:
        raise ValueError(f"A and U must both have shape (n_samples, n_sections); got {A.shape} and {U.shape}")
    ex = section_exponents()
    # (n, s, 23): powers by broadcasting, no loop over samples.
    cols = A[:, :, None] ** ex[:, 0] * U[:, :, None] ** ex[:, 1]
    return cols.reshape(A.shape[0], -1)
