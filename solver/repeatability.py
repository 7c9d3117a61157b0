"""The uncertainty of an ISO 9283 pose repeatability RP = l_bar + 3 S_l from n visits of a point.

Two parts. The sampling of n visits, by a parametric bootstrap: the visits scatter as a 3-D
Gaussian of the covariance they show; RP taken on n draws of it, as the procedure takes it (the
distances to the draws' own barycentre), against the RP of that scatter itself (its distances to
its true centre, many draws) gives the ratio's distribution, whose quantiles turn the figure into
an interval for the arm's RP (RP scales with the scatter, so the ratio hardly depends on it:
a pivot). Few visits tend to show RP low (the barycentre sits among them), so the interval is
lopsided, and U is given below and above the figure. And the tracker: its own random error
(per-axis sigma at the point's range, from its specification) is in every visit's reading, so
it can only have widened the spread: the arm's own RP may lie lower, by as much as removing a
scatter of that sigma from the interval's lower end takes away (independent isotropic scatters
add their RP in quadrature), never higher; that part enters below the figure only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

COVERAGE = 0.95
DRAWS = 2000  # bootstrap sets of n visits per point: quantiles at 2.5 % to about 1 % of RP
POPULATION = 20_000  # draws of the scatter itself, for its RP
# RP of an isotropic Gaussian scatter of per-axis sigma 1: its distance's mean and 3 standard
# deviations (a Maxwell distribution): 2 sqrt(2 / pi) + 3 sqrt(3 - 8 / pi) = 3.616
RP_PER_SIGMA = 2.0 * np.sqrt(2.0 / np.pi) + 3.0 * np.sqrt(3.0 - 8.0 / np.pi)


@dataclass(frozen=True)
class RepeatabilityUncertainty:
    """Per point (mm): RP, and the expanded uncertainty below and above it at `coverage`."""

    rp: np.ndarray
    below: np.ndarray  # U-: the arm's RP lies no lower than rp - below (with the coverage)
    above: np.ndarray  # U+: and no higher than rp + above
    sampling_below: np.ndarray  # the visits' part of U- alone (the tracker's left out)
    coverage: float


def rp_of(attained: np.ndarray) -> np.ndarray:
    """RP = l_bar + 3 S_l of visits (..., n, 3) about their own barycentre."""
    d = np.linalg.norm(attained - attained.mean(axis=-2, keepdims=True), axis=-1)
    return d.mean(axis=-1) + 3.0 * d.std(axis=-1, ddof=1)


def rp_uncertainty(
    attained, tracker_sigma_mm=0.0, coverage: float = COVERAGE, seed: int = 0
) -> RepeatabilityUncertainty:
    """U below and above the RP of each point's visits (p, n, 3) mm, the tracker's per-axis
    random error tracker_sigma_mm (per point or one for all) on top; seeded, so the same
    visits give the same U."""
    a = np.asarray(attained, dtype=float)
    p, n = a.shape[:2]
    if n < 2:
        raise ValueError("repeatability needs at least two visits a point")
    rng = np.random.default_rng([seed, 9283])
    rp = rp_of(a)
    tail = (1.0 - coverage) / 2.0
    lo, hi = np.empty(p), np.empty(p)
    for j in range(p):
        dev = a[j] - a[j].mean(axis=0)
        w, v = np.linalg.eigh(dev.T @ dev / (n - 1))
        root = v * np.sqrt(np.clip(w, 0.0, None))  # root @ root.T: the visits' covariance
        sets = rng.normal(size=(DRAWS, n, 3)) @ root.T
        d = np.linalg.norm(rng.normal(size=(POPULATION, 3)) @ root.T, axis=-1)
        ratio = rp_of(sets) / (d.mean() + 3.0 * d.std(ddof=1))
        lo[j], hi[j] = np.quantile(ratio, [tail, 1.0 - tail])
    sampling = rp - rp / hi
    above = rp / lo - rp
    tracker = RP_PER_SIGMA * np.broadcast_to(np.asarray(tracker_sigma_mm, dtype=float), rp.shape)
    # the lower end of the spread's own RP, less the most the tracker's noise can have added
    lowest = np.sqrt(np.clip((rp - sampling) ** 2 - tracker**2, 0.0, None))
    return RepeatabilityUncertainty(rp, rp - lowest, above, sampling, coverage)
