"""Whether a deployed model still describes the arm: the statistics of a quick check.

A check measures the same few poses every time. Its errors against the model have two parts: the
model's own error at those poses, fixed from check to check, and the scatter of the arm and the
tracker, fresh each time. So a check is judged twice: its level against the model's held-out error
(has the model ever described these poses?), and its change from the first checks of the model
against the scatter between checks (has the arm changed since?), the latter accumulated over the
history by a one-sided CUSUM so that a small lasting change trips it within a few checks while a
clean arm almost never does. A change is then explained, where it can be, by the fewest
parameters that leave only scatter: one joint's zero, a scale (the cell warming), or a rigid
motion of every point (the tracker or the base moved).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import stats

# The scatter of a pose repeated (3-D RMS, mm) before the history shows its own: the pose
# repeatability of an industrial arm, as the data sheets give it (ISO 9283), is 0.02-0.05 mm.
REPEATABILITY_MM = 0.03
# A quick check's pose is one 3-D vector of model error: its SMRs move together on the flange.
LEVEL_WATCH_P = 1e-2
LEVEL_RECALIBRATE_P = 1e-4
# CUSUM of the change's normal score: allowance K, limits for watch and recalibrate. With K 0.5
# and H 6 a clean arm's average run to a false alarm is about a thousand checks; a change of
# two standard scores trips it in about three, a large one at once (JUMP).
CUSUM_K = 0.5
CUSUM_WATCH = 3.0
CUSUM_H = 6.0
Z_WATCH = stats.norm.isf(LEVEL_WATCH_P)
Z_JUMP = stats.norm.isf(1e-6)
PRIOR_DOF = 3.0  # the degrees of freedom the repeatability guess weighs as
POSE_PRIOR_DOF = 6.0  # those a pose's own scatter is shrunk toward the pooled one with
BASELINE_CHECKS = 3  # the first checks of a model, which later ones are compared with (at most)
ADEQUATE_P = 1e-3  # a change explained when what is left is as likely as this from scatter
# A cause that another contains (joint 1's zero is a rigid turn about axis 1) gives way to it when
# the larger fits the change better than scatter would by this chance (F test): a shifted
# tracker is no joint-1 zero because a turn about axis 1 leaves scatter-sized residuals
NESTED_P = 1e-2
Z_CAP = 38.0  # normal scores beyond this are rounding (sf below 1e-300)


@dataclass(frozen=True)
class Level:
    """A check's error against the model: RMS and max (mm) over its readings and the verdict."""

    rms_mm: float
    max_mm: float
    p_value: float  # of an RMS this large from the model's held-out error
    verdict: str  # ok, watch, recalibrate


@dataclass(frozen=True)
class Change:
    """A check's change from the model's first checks, and the history's CUSUM after it."""

    rms_mm: float  # 3-D RMS of the change over the matched readings
    scatter_mm: float  # the 3-D RMS scatter between checks it is judged against
    z: float  # normal score of the change (0 when nothing to compare with)
    cusum: float
    verdict: str
    diff: np.ndarray  # (p, 3) the change of each compared pose
    var_change: np.ndarray  # (p,) per coordinate, the variance of each compared pose's change
    compared: np.ndarray  # (P,) bool: the poses compared (those a baseline check has)


@dataclass(frozen=True)
class Explanation:
    """The simplest change model that leaves only scatter, and its parameters."""

    kind: str  # rigid, joint, scale, or unknown
    joint: int | None  # 1-based, for a joint's zero
    values: np.ndarray  # the fitted parameters (rad, unitless, or rigid: rad x3, mm x3)
    rms_left_mm: float


def score(sf: float) -> float:
    """The normal score of a survival probability, capped where it is only rounding."""
    return float(min(Z_CAP, stats.norm.isf(max(sf, 1e-300))))


def level(err: np.ndarray, pose: np.ndarray, expected_mm: float) -> Level:
    """Judge the errors err (n, 3) mm of a check's readings (pose: each reading's pose index)
    against the model's expected held-out 3-D RMS: each pose's mean error is one vector."""
    err = np.asarray(err, dtype=float)
    per = np.linalg.norm(err, axis=1)
    rms, mx = float(np.sqrt(np.mean(per**2))), float(per.max())
    poses = np.unique(pose)
    mean = np.array([err[pose == p].mean(axis=0) for p in poses])
    nu = 3 * len(poses)
    chi = float(np.sum(mean**2) / (expected_mm**2 / 3.0))
    p = float(stats.chi2.sf(chi, nu))
    verdict = "recalibrate" if p < LEVEL_RECALIBRATE_P else "watch" if p < LEVEL_WATCH_P else "ok"
    return Level(rms, mx, p, verdict)


def level_limits(expected_mm: float, poses: int) -> tuple[float, float]:
    """The 3-D RMS of a check's pose errors (mm) at which `level` says watch, and recalibrate,
    for a check of this many poses against the model's expected error."""
    nu = 3 * poses
    watch, recal = (
        expected_mm * float(np.sqrt(stats.chi2.isf(p, nu) / nu))
        for p in (LEVEL_WATCH_P, LEVEL_RECALIBRATE_P)
    )
    return watch, recal


def scatter_variance(history: np.ndarray, prior_mm: float) -> tuple[np.ndarray, float]:
    """Per pose, the per-coordinate variance of the scatter between checks, and the degrees of
    freedom it is known with.

    history: earlier clean checks' pose errors (c, P, 3) (NaN where one lacks a pose). The
    prior (3-D RMS prior_mm) weighs as one pose seen twice: a guess, which a few checks' own
    scatter outweighs. Each pose's own scatter (the arm's repeatability grows with reach) is
    shrunk toward the pooled one by POSE_PRIOR_DOF.
    """
    H = np.asarray(history, dtype=float)
    var0 = prior_mm**2 / 3.0
    if len(H) < 2:
        return np.full(H.shape[1], var0), PRIOR_DOF
    have = np.isfinite(H[..., 0])
    counts = have.sum(axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a pose no clean check has
        mean = np.nanmean(np.where(have[..., None], H, np.nan), axis=0)
    dev = np.where(have[..., None], H - mean[None], 0.0)
    own = np.sum(dev**2, axis=(0, 2))  # (P,)
    nu_own = 3.0 * np.maximum(counts - 1, 0)
    pooled = (PRIOR_DOF * var0 + own.sum()) / (PRIOR_DOF + nu_own.sum())
    var = (POSE_PRIOR_DOF * pooled + own) / (POSE_PRIOR_DOF + nu_own)
    return var, float(np.mean(POSE_PRIOR_DOF + nu_own))


def change(
    err: np.ndarray,
    baseline: np.ndarray,
    n_baseline: np.ndarray,
    var: np.ndarray,
    nu_var: float,
    cusum_before: float,
) -> Change:
    """The change err - baseline (P, 3) judged against the scatter var (P,) (per coordinate,
    nu_var degrees of freedom), a baseline of n_baseline (P,) checks a pose, and the CUSUM."""
    d = np.asarray(err, dtype=float) - baseline
    scale = np.asarray(var, dtype=float) * (1.0 + 1.0 / np.asarray(n_baseline, dtype=float))
    T = float(np.sum(d**2 / scale[:, None]))
    nu = d.size
    z = score(float(stats.f.sf(T / nu, nu, nu_var)))
    s = max(0.0, cusum_before + z - CUSUM_K)
    if s > CUSUM_H or z > Z_JUMP:
        verdict = "recalibrate"
    elif s > CUSUM_WATCH or z > Z_WATCH:
        verdict = "watch"
    else:
        verdict = "ok"
    rms = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    every = np.ones(len(d), dtype=bool)
    scatter = float(np.sqrt(3.0 * np.mean(var)))
    return Change(rms, scatter, z, s, verdict, d, scale, every)


def since_baseline(
    now: np.ndarray, past: np.ndarray, history: list[tuple[float, float]], prior_mm: float
) -> Change | None:
    """The change of a check's pose errors now (P, 3) from the model's first checks, judged over
    the earlier checks' errors past (c, P, 3) (NaN where one lacks a pose) and their (score,
    CUSUM); None when no baseline check shares two poses with it."""
    past = np.asarray(past, dtype=float)
    base = past[: baseline_checks(history)]
    n_base = np.isfinite(base[..., 0]).sum(axis=0)
    ok = n_base > 0
    if len(past) == 0 or ok.sum() < 2:
        return None
    # the scatter from the checks before the first change found: leaving out only the checks
    # that look high would bias it low and then trip on clean checks
    var, nu = scatter_variance(past[: first_change(history)][:, ok], prior_mm)
    mean = np.array([np.mean(b[np.isfinite(b[:, 0])], axis=0) for b in base[:, ok].swapaxes(0, 1)])
    c = change(now[ok], mean, n_base[ok], var, nu, history[-1][1])
    return Change(c.rms_mm, c.scatter_mm, c.z, c.cusum, c.verdict, c.diff, c.var_change, ok)


def baseline_checks(history: list[tuple[float, float]]) -> int:
    """How many of the first checks the baseline is (the model's own error at the check's poses):
    BASELINE_CHECKS, ending before the first check whose change tripped recalibrate. A moved arm
    is no reference: two clean checks, then two moved 0.15 mm, and the fourth measured its move
    from a baseline holding the third, as 0.100 mm."""
    return min(BASELINE_CHECKS, first_change(history))


def first_change(history: list[tuple[float, float]]) -> int:
    """Index of the first check whose change (score, CUSUM) tripped recalibrate (len if none)."""
    for i, (z, s) in enumerate(history):
        if s > CUSUM_H or z > Z_JUMP:
            return i
    return len(history)


def rigid_columns(points: np.ndarray) -> np.ndarray:
    """(3n, 6) the motion of points (n, 3) mm under a small rotation (rad) about their centroid
    and a translation (mm)."""
    c = points - points.mean(axis=0)
    n = len(points)
    A = np.zeros((n, 3, 6))
    # w x c = [[0, -wz, wy], [wz, 0, -wx], [-wy, wx, 0]] c
    A[:, 0, 1], A[:, 0, 2] = c[:, 2], -c[:, 1]
    A[:, 1, 0], A[:, 1, 2] = -c[:, 2], c[:, 0]
    A[:, 2, 0], A[:, 2, 1] = c[:, 1], -c[:, 0]
    A[:, :, 3:] = np.eye(3)
    return A.reshape(3 * n, 6)


def explain(
    d: np.ndarray, var, candidates: dict[tuple[str, int | None], np.ndarray]
) -> list[Explanation]:
    """The simplest candidates (fewest columns) whose fit of the change d (n, 3) leaves what the
    scatter (var per coordinate of d: a number, or one per row of d) explains, best first: one
    names the cause, several say the data cannot tell them apart, none that no candidate
    explains it. Each row is weighed by its scatter. candidates: (kind, joint) -> (3n, k)."""
    w = 1.0 / np.sqrt(np.repeat(np.broadcast_to(np.asarray(var, dtype=float), (len(d),)), 3))
    y = np.asarray(d, dtype=float).ravel() * w
    found: list[tuple[float, Explanation]] = []
    for k in sorted({A.shape[1] for A in candidates.values()}):
        for (kind, joint), A in candidates.items():
            nu = len(y) - k
            if A.shape[1] != k or nu <= 0:
                continue
            coef, *_ = np.linalg.lstsq(A * w[:, None], y, rcond=None)
            r = y - (A * w[:, None]) @ coef
            if float(stats.chi2.sf(float(r @ r), nu)) >= ADEQUATE_P:
                left = r / w
                left = float(np.sqrt(np.mean(np.sum(left.reshape(-1, 3) ** 2, axis=1))))
                found.append((float(r @ r), Explanation(kind, joint, coef, left)))
        if found:
            break
    found = [_widened(f, y, w, candidates) for f in found]
    return [e for _, e in sorted(found, key=lambda f: f[0])]


def _widened(f: tuple[float, Explanation], y, w, candidates) -> tuple[float, Explanation]:
    """f, or the candidate that contains it (its columns within the other's span) and fits y
    significantly better (F test at NESTED_P)."""
    rss, e = f
    A = candidates[(e.kind, e.joint)] * w[:, None]
    for (kind, joint), B in candidates.items():
        Bw = B * w[:, None]
        k, K = A.shape[1], B.shape[1]
        nu = len(y) - K
        if K <= k or nu <= 0:
            continue
        inside = np.linalg.lstsq(Bw, A, rcond=None)[0]
        if np.linalg.norm(A - Bw @ inside) > 1e-6 * np.linalg.norm(A):
            continue
        coef = np.linalg.lstsq(Bw, y, rcond=None)[0]
        r = y - Bw @ coef
        big = float(r @ r)
        F = ((rss - big) / (K - k)) / max(big / nu, 1e-300)
        if float(stats.f.sf(F, K - k, nu)) < NESTED_P:
            left = float(np.sqrt(np.mean(np.sum((r / w).reshape(-1, 3) ** 2, axis=1))))
            return big, Explanation(kind, joint, coef, left)
    return f
