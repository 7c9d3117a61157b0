"""A fleet of arms of one model: each arm's identified parameters against the fleet's robust
centre and spread, and each arm's jump from its previous calibration (arrays in, arrays out)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.stats import norm

# the chance that a fleet of clean arms shows any flag at all, over every arm and parameter
FAMILY_RATE = 0.01
# fewer arms than this give no spread worth judging against (at 5 the limit is 60 spreads)
MIN_ARMS = 8
# Rousseeuw and Croux's Qn: the normal's standard deviation over the pairwise differences'
# first quartile (asymptotically; spread_calibration corrects it for the fleet's size)
QN_SCALE = 2.2219
# clean fleets drawn to set the limit: about 50 beyond it at 21 parameters and FAMILY_RATE
LIMIT_DRAWS = 100_000
LIMIT_SEED = 23
# a larger fleet is judged with this size's limit, which is larger than its own (conservative):
# the draws' pairwise differences grow with the square of the size
LIMIT_ARMS_MAX = 20


@dataclass(frozen=True)
class FleetSpread:
    """Per parameter (columns) the fleet's median, robust spread (Qn) and limit; per arm (rows)
    its deviation in units of sqrt(spread^2 + se^2) and whether beyond the limit."""

    centre: np.ndarray  # (P,)
    spread: np.ndarray  # (P,) Qn, the parameter's units
    arms: np.ndarray  # (P,) arms with a value of the parameter
    limit: np.ndarray  # (P,) |z| beyond which an arm is flagged; nan with too few arms
    z: np.ndarray  # (A, P) nan where the arm has no value
    flagged: np.ndarray  # (A, P) bool


@dataclass(frozen=True)
class Jumps:
    """Per arm and parameter, the change from the previous calibration and its z."""

    delta: np.ndarray  # (A, P) nan where either calibration lacks the parameter
    z: np.ndarray  # (A, P) delta / sqrt(se1^2 + se2^2)
    limit: float
    flagged: np.ndarray  # (A, P) bool


def qn_raw(values: np.ndarray) -> np.ndarray:
    """Per row of (rows, n) values, Qn without its small-sample correction: the first quartile
    of the pairwise distances (50% breakdown, like the MAD, but 82% efficient against 37%)."""
    n = values.shape[1]
    i, j = np.triu_indices(n, 1)
    h = n // 2 + 1
    k = h * (h - 1) // 2
    pairs = np.abs(values[:, i] - values[:, j])
    return QN_SCALE * np.partition(pairs, k - 1, axis=1)[:, k - 1]


@lru_cache(maxsize=64)
def spread_calibration(
    n_arms: int, n_parameters: int, family_rate: float = FAMILY_RATE
) -> tuple[float, float]:
    """For a parameter known on n_arms arms: the Qn's small-sample factor (its mean on standard
    normals), and the |z| limit such that a clean Gaussian fleet flags any of n_parameters
    independent parameters with probability family_rate.

    Drawn, not a normal quantile: the scale of ten values scatters, so |z| has much heavier
    tails than a normal (8.6 at 10 arms and 21 parameters, 5.9 at 20, against the normal's 4.1)."""
    if n_arms < MIN_ARMS:
        return 1.0, float("nan")
    n = min(n_arms, LIMIT_ARMS_MAX)
    # per parameter the chance left so that all n_parameters stay clean with 1 - family_rate
    per_parameter = 1.0 - (1.0 - family_rate) ** (1.0 / n_parameters)
    draws = np.random.default_rng(LIMIT_SEED).standard_normal((LIMIT_DRAWS, n))
    raw = qn_raw(draws)
    factor = float(np.mean(raw))
    centre = np.median(draws, axis=1, keepdims=True)
    worst = np.max(np.abs(draws - centre), axis=1) / (raw / factor)
    return factor, float(np.quantile(worst, 1.0 - per_parameter))


def jump_limit(n_tests: int, family_rate: float = FAMILY_RATE) -> float:
    """The |z| limit on a change between two calibrations, Bonferroni over n_tests changes (the
    standard errors are known, so the normal quantile holds)."""
    return float(norm.isf(family_rate / (2.0 * max(n_tests, 1))))


def fleet_spread(values: np.ndarray, se: np.ndarray, family_rate: float = FAMILY_RATE):
    """The fleet's spread of (arms, parameters) values with their standard errors (nan where
    an arm lacks a parameter); an arm beyond a parameter's limit is flagged.

    The spread already holds the arms' estimation scatter; adding each arm's own se^2 makes an
    arm with a poorly determined parameter no more suspect than its uncertainty says."""
    values = np.asarray(values, dtype=float)
    se = np.asarray(se, dtype=float)
    if values.shape != se.shape or values.ndim != 2:
        raise ValueError("values and standard errors must both be (arms, parameters)")
    present = np.isfinite(values)
    arms = present.sum(axis=0)
    judged = int(np.count_nonzero(arms >= MIN_ARMS))
    centre = np.full(values.shape[1], np.nan)
    spread = np.full(values.shape[1], np.nan)
    limit = np.full(values.shape[1], np.nan)
    for p in np.flatnonzero(arms):
        column = values[present[:, p], p]
        centre[p] = np.median(column)
        factor, limit[p] = spread_calibration(int(arms[p]), judged, family_rate)
        spread[p] = qn_raw(column[None, :])[0] / factor if arms[p] > 1 else 0.0
    own = np.where(np.isfinite(se), se, 0.0)
    scale = np.sqrt(spread**2 + own**2)
    dev = values - centre
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(scale > 0, dev / scale, np.where(dev == 0, 0.0, np.inf * np.sign(dev)))
    z = np.where(present, z, np.nan)
    flagged = np.abs(np.nan_to_num(z)) > np.nan_to_num(limit, nan=np.inf)
    return FleetSpread(centre, spread, arms, limit, z, flagged)


def jumps(
    previous: np.ndarray,
    previous_se: np.ndarray,
    latest: np.ndarray,
    latest_se: np.ndarray,
    family_rate: float = FAMILY_RATE,
) -> Jumps:
    """Each arm's change from its previous calibration (rows of nan: none) in units of
    sqrt(se1^2 + se2^2), flagged beyond the Bonferroni limit over every change compared."""
    delta = np.asarray(latest, dtype=float) - np.asarray(previous, dtype=float)
    sigma = np.hypot(np.asarray(previous_se, dtype=float), np.asarray(latest_se, dtype=float))
    known = np.isfinite(delta) & np.isfinite(sigma)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(sigma > 0, delta / sigma, np.where(delta == 0, 0.0, np.inf * np.sign(delta)))
    z = np.where(known, z, np.nan)
    limit = jump_limit(int(np.count_nonzero(known)), family_rate)
    return Jumps(np.where(known, delta, np.nan), z, limit, np.abs(np.nan_to_num(z)) > limit)
