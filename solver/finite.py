"""Finite checks in front of the linear algebra: LAPACK's iterative routines (SVD, eigh) may never
return on a matrix holding inf or NaN, so nothing non-finite reaches them; a clear ValueError does.
"""

from __future__ import annotations

import numpy as np

# Coordinates and lengths in mm. A million kilometres is beyond any instrument, and keeps every
# square, cross product and sum over a campaign of such numbers far inside the float range.
MAX_MM = 1e9


class NonFinite(ValueError):
    """Inputs or an intermediate product the numerics cannot use (inf, NaN, or out of range)."""


def require_finite(what: str, *arrays) -> None:
    """Raise NonFinite "non-finite values in <what>" unless every entry of every array is finite."""
    for a in arrays:
        if not np.isfinite(a).all():
            raise NonFinite(f"non-finite values in {what}")


def finite(a, what: str):
    """`a` itself, checked as require_finite does: for use inside a linear-algebra call."""
    require_finite(what, a)
    return a


def require_measured(what: str, meas, limit: float | None = None) -> None:
    """Measured coordinates (mm; NaN marks a missing reading): none infinite, none beyond limit."""
    limit = MAX_MM if limit is None else limit
    a = np.asarray(meas, dtype=float)
    if np.isinf(a).any():
        raise NonFinite(f"non-finite values in {what}")
    with np.errstate(invalid="ignore"):
        big = np.abs(a) > limit
    if big.any():
        worst = float(np.nanmax(np.abs(a)))
        raise NonFinite(
            f"{what}: a coordinate of {worst:.3g} mm is beyond {limit:.0g} mm; "
            "no instrument measures that far"
        )


def require_inputs(q, meas, targets=None, base_guess=None) -> None:
    """The checks every solver entry point makes on its data before any fit."""
    require_finite("the joint angles", q)
    require_measured("the measured SMR positions", meas)
    if targets is not None:
        require_finite("the nominal SMR positions", targets)
        require_measured("the nominal SMR positions", targets)
    if base_guess is not None:
        require_finite("the base guess", base_guess)
        require_measured("the base guess", np.asarray(base_guess)[:3, 3])
