"""The uncertainty of an ISO 9283 RP holds what it states: over simulated points visited n times
(isotropic and flattened scatters), the interval [RP - U-, RP + U+] holds the scatter's own RP
in about 95 % of points (too narrow an interval fails the same check); the tracker's noise
widens U- only, so that a still arm read through a noisy tracker is not said to scatter."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from robocal.solver.repeatability import RP_PER_SIGMA, rp_uncertainty

SHAPES = ((1.0, 1.0, 1.0), (1.0, 0.5, 0.2), (1.0, 0.1, 0.1))
POINTS = 300  # per shape and visit count: the coverage to about +- 1.3 %


@cache
def population_rp(shape: tuple[float, float, float]) -> float:
    """RP of the scatter itself: distances to its true centre, two million draws."""
    d = np.linalg.norm(np.random.default_rng(1).normal(size=(2_000_000, 3)) * shape, axis=1)
    return float(d.mean() + 3.0 * d.std())


@cache
def intervals(n: int) -> list:
    """Per shape: its RP and the uncertainties of POINTS points visited n times (kept: the
    too-narrow check narrows the very intervals the coverage check judged)."""
    rng = np.random.default_rng([n, 5])
    return [
        (population_rp(shape), rp_uncertainty(rng.normal(size=(POINTS, n, 3)) * shape, seed=n))
        for shape in SHAPES
    ]


def covered(n: int, narrower: float = 1.0) -> float:
    hits = []
    for truth, u in intervals(n):
        low, high = u.rp - narrower * u.below, u.rp + narrower * u.above
        hits.append((low <= truth) & (truth <= high))
    return float(np.mean(hits))


@pytest.mark.parametrize("n", [6, 9])
def test_the_interval_holds_the_arms_rp_95_percent_of_the_time(n):
    c = covered(n)
    print(f"\nn = {n}: RP within its U at {c:.3f} of points")
    assert 0.92 <= c <= 0.99


def test_an_interval_too_narrow_fails_the_same_check():
    assert covered(9, narrower=0.5) < 0.9


def test_the_trackers_noise_widens_only_the_lower_side():
    rng = np.random.default_rng(3)
    still = rng.normal(size=(200, 9, 3)) * 0.01  # a still arm: only the tracker's 10 µm
    plain, tracked = rp_uncertainty(still), rp_uncertainty(still, tracker_sigma_mm=0.01)
    assert np.array_equal(plain.above, tracked.above)
    assert np.all(tracked.below >= plain.below)
    # the arm's own RP (0) is within the interval once the tracker is accounted for
    assert np.mean(tracked.rp - tracked.below <= 1e-12) > 0.95
    assert np.mean(plain.rp - plain.below <= 1e-12) < 0.05
    assert RP_PER_SIGMA == pytest.approx(population_rp((1.0, 1.0, 1.0)), rel=2e-3)
