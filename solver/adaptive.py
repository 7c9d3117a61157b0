"""An adaptive campaign's numerics: which poses to measure next, the accuracy the model will
have on new poses over the working volume, and when to stop.

The fit's identified parameters (its identifiable subset, as its covariance has them) move each
reading's point by J_r dx. With readings of noise variance s^2 per coordinate, least squares
leaves the parameters a covariance s^2 C, C = (J'J)^-1, and a new reading at the working volume
an expected squared error of noise^2 + s^2 tr(W C), W the mean J_r'J_r over the volume's
readings (I-optimality: the mean prediction variance). The pose that most reduces tr(W C) is
measured next (Woodbury, so each candidate costs its own rows only).

The prediction is checked by the data's own leave-one-pose-out residuals (guard.py's, in closed
form): under the same assumptions a training pose's held-out residual (I - H_p)^-1 r_p has
expected squared length s^2 tr((I - H_p)^-1): s^2 x 3 of it the noise's, the rest the
parameters'. What the data's held-out residuals show beyond it is put on the parameters (errors
a pose's readings share, the arm's own scatter, leave them less certain than independent noise
would): their part of the prediction is scaled by kappa (>= 1), and the noise's part, the floor
the prediction tends to with endless poses, is not (it is the spec's and the residuals', counted
once).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from .finite import finite
from .guard import MIN_EQUATIONS_PER_PARAMETER

# The floor is "reached" once the parameters' share of the predicted squared error is below
# this: the predicted RMS is then within 5 % of the floor, and more poses gain at most that.
FLOOR_SHARE = 0.1
# The rule stops on the prediction's one-sided upper bound: the predicted RMS plus Z of its
# relative standard uncertainty, 1 / sqrt(2 poses) (an RMS over that many poses' errors, which
# the arm's scatter makes the independent draws, not the readings).
Z = 1.0
# Poses per identified parameter before the rule may stop: a pose's readings share the arm's
# scatter, so poses are the independent draws, and the pose-clustered covariance sees at most
# one direction of error per pose (below this, simulated campaigns of 3-4 SMRs stopped at 10
# poses with the accuracy under-predicted by a third).
MIN_POSES_PER_PARAMETER = 0.5
# The fit's residuals count as showing an error beyond the tracker's noise when their sum of
# squares exceeds the noise's (1 - this) chi-square quantile at their degrees of freedom.
EXCESS_ALPHA = 0.05
# The held-out check scales the parameters' part only when its mean square exceeds what the
# noise alone gives it by this many of that statistic's standard deviations (one-sided 1 %).
Z_HOLDOUT = 2.33
# Relative ridge on J'J's diagonal: a seed set just short of full rank still gives a finite C.
RIDGE = 1e-10


@dataclass(frozen=True)
class Prediction:
    """The predicted held-out accuracy over the working volume, 3-D RMS per reading (mm)."""

    rms_mm: float  # predicted held-out RMS at new poses over the working volume
    floor_mm: float  # what rms_mm tends to with endless poses: a new reading's error
    parameters_mm: float  # the parameters' part: sqrt(mean prediction variance) x kappa
    noise_mm: float  # the tracker's noise over the volume, 3-D RMS a reading
    error_mm: float  # a new reading's error: that noise, and what the fit's residuals show beyond
    holdout_mm: float  # the data's own leave-one-pose-out RMS
    expected_holdout_mm: float  # what the noise alone would give it
    kappa: float  # >= 1: the scale the data's held-out check puts on the parameters' part
    poses: int  # the poses fitted
    equations: int  # the fit's equations (3 a reading)
    parameters: int  # its identified parameters

    @property
    def upper_mm(self) -> float:
        """The one-sided upper bound the rule holds against the target."""
        return self.rms_mm * (1.0 + Z / np.sqrt(2.0 * max(1, self.poses)))

    @property
    def supported(self) -> bool:
        """Whether the fit has the equations per parameter a deployable model needs (guard.py)
        and the poses per parameter above: fewer, and its checks have too little to say."""
        return (
            self.equations >= MIN_EQUATIONS_PER_PARAMETER * self.parameters
            and self.poses >= MIN_POSES_PER_PARAMETER * self.parameters
        )


@dataclass(frozen=True)
class Decision:
    """Whether the campaign stops, and why: "target", "floor", "maximum" or "" (go on)."""

    stop: bool
    reason: str
    message: str


def rows_of(J, mask=None) -> np.ndarray:
    """Per-reading Jacobians (m, K, 3, P) as per-pose rows (m, 3K, P), a missing reading's rows
    (mask (m, K) False) zero: they add nothing to J'J and leave no residual."""
    J = np.asarray(J, dtype=float)
    if mask is not None:
        J = J * np.asarray(mask, dtype=bool)[:, :, None, None]
    m, K, _, P = J.shape
    return J.reshape(m, 3 * K, P)


def normal_inverse(J_rows: np.ndarray) -> np.ndarray:
    """C = (J'J)^-1 of per-pose rows (m, r, P), Jacobi-scaled, with a tiny ridge."""
    M = np.einsum("nrp,nrq->pq", J_rows, J_rows)
    d = np.sqrt(np.abs(np.diag(finite(M, "the information matrix"))))
    d[d == 0] = 1.0
    S = M / np.outer(d, d) + RIDGE * np.eye(len(M))
    return np.linalg.inv(S) / np.outer(d, d)


def volume_weight(J_rows: np.ndarray, readings: int) -> np.ndarray:
    """W (P, P): the mean of J_r'J_r over the working volume's readings (poses' rows (m, r, P),
    `readings` readings in all), so tr(W C) is the mean 3-D prediction variance per unit s^2."""
    return np.einsum("nrp,nrq->pq", J_rows, J_rows) / max(1, readings)


def expected_holdout(J_rows: np.ndarray, C: np.ndarray, readings: int) -> float:
    """Mean squared held-out residual per reading, per unit s^2 per coordinate: the mean of
    tr((I - H_p)^-1) with H_p = J_p C J_p' (a missing reading's rows are zero and add 1 each
    to the trace, so they are taken off)."""
    H = np.einsum("nrp,pq,nsq->nrs", J_rows, C, J_rows)
    present = np.any(J_rows != 0, axis=-1)  # (m, r)
    eye = np.eye(H.shape[-1])
    inv = np.linalg.inv(eye - H)
    diag = np.einsum("nrr->nr", inv)
    return float(np.sum(diag * present)) / max(1, readings)


def holdout_spread(J_rows: np.ndarray, C: np.ndarray, readings: int) -> float:
    """The standard deviation of the leave-one-pose-out mean square per reading, per unit s^2,
    under the noise alone: the held-out residuals are B e, B = D^-1 (I - H) (D the poses' blocks
    of I - H), so their sum of squares is a quadratic form e'Qe, Q = B'B, of variance
    2 s^4 tr(Q^2)."""
    m, r, P = J_rows.shape
    A = J_rows.reshape(m * r, P)
    present = np.any(A != 0, axis=1)
    A, pose = A[present], np.repeat(np.arange(m), r)[present]
    M = np.eye(len(A)) - A @ C @ A.T
    B = np.zeros_like(M)
    for p in range(m):
        rows = np.flatnonzero(pose == p)
        if rows.size:
            B[rows] = np.linalg.solve(M[np.ix_(rows, rows)], M[rows])
    Q = B.T @ B
    return float(np.sqrt(2.0 * np.sum(Q * Q))) / max(1, readings)


def holdout_rms(
    J_rows: np.ndarray, C: np.ndarray, residual_rows: np.ndarray, readings: int
) -> float:
    """The leave-one-pose-out RMS (3-D, a reading) of a linear(ised) fit, in closed form: pose
    p's held-out residual is (I - H_p)^-1 r_p, H_p = J_p C J_p' (rows (m, r, P), residuals
    (m, r), a missing reading's rows and residual zero)."""
    H = np.einsum("nrp,pq,nsq->nrs", J_rows, C, J_rows)
    held = np.linalg.solve(np.eye(H.shape[-1]) - H, residual_rows[..., None])[..., 0]
    return float(np.sqrt(np.sum(held**2) / max(1, readings)))


def predict(
    J_train: np.ndarray,
    train_readings: int,
    W: np.ndarray,
    noise_mm: float,
    holdout_mm: float,
    fit_rms_mm: float = 0.0,
    volume_noise_mm: float | None = None,
) -> Prediction:
    """The held-out RMS a fit on J_train (poses' rows (m, r, P)) will have over the volume of
    W, given the tracker's noise at the training readings and over the volume (3-D RMS a
    reading; the volume's default the training's), the fit's RMS and its held-out RMS.

    A training reading's error is the tracker's noise, or what the fit's residuals show if they
    show more than that noise would leave them at EXCESS_ALPHA (their unbiased estimate, RMS x
    sqrt(rows / (rows - P))): at a seed set's few dozen degrees of freedom, taking the larger of
    the two every time added the noise's own scatter to the prediction (one SMR: 10 % high on
    average). The excess (the arm's own scatter, an effect no parameter has) is added to the
    volume's noise, since the poses chosen for what they teach lie farther from the tracker
    than most, and a tracker's noise grows with range.

    Errors shared by a pose's readings leave the parameters more uncertain than independent
    noise would: the held-out check, which holds out whole poses, sees that. Its excess over
    what the noise and the parameters' variance give it scales the parameters' part alone (the
    noise's part is the spec's and the residuals', counted once): kappa^2 = (holdout^2 - noise
    part) / parameters' part, at least 1, and only when the excess is beyond Z_HOLDOUT of the
    statistic's own spread under the noise (holdout_spread): the parameters' part is a small
    share of the held-out residuals, so that spread, put on it, made kappa up to 1.5 on clean
    seed sets of 16 poses of 2 SMRs (predictions 25-33 % high). (The pose-clustered covariance, tried in its place,
    needs more poses than parameters: at a seed set's 16 poses it over-predicted by a third.)"""
    rows = 3 * train_readings
    dof = rows - J_train.shape[-1]
    s2 = noise_mm**2 / 3.0
    if dof > 0 and np.isfinite(fit_rms_mm):
        shown = fit_rms_mm**2 * rows / dof / 3.0
        if shown * dof > s2 * float(chi2.ppf(1.0 - EXCESS_ALPHA, dof)):
            s2 = shown
    unexplained2 = max(0.0, 3.0 * s2 - noise_mm**2)
    vol = noise_mm if volume_noise_mm is None else volume_noise_mm
    error_mm = float(np.sqrt(vol**2 + unexplained2))
    C = normal_inverse(J_train)
    par2 = s2 * float(np.trace(W @ C))
    per_reading = expected_holdout(J_train, C, train_readings)  # 3 (the noise) + parameters'
    expected = np.sqrt(s2 * per_reading)
    k2 = 1.0
    spread = holdout_spread(J_train, C, train_readings)
    if (
        np.isfinite(holdout_mm)
        and per_reading > 3.0
        and holdout_mm**2 > s2 * (per_reading + Z_HOLDOUT * spread)
    ):
        k2 = max(1.0, (holdout_mm**2 - 3.0 * s2) / (s2 * (per_reading - 3.0)))
    kappa = float(np.sqrt(k2))
    return Prediction(
        rms_mm=float(np.sqrt(error_mm**2 + k2 * par2)),
        floor_mm=error_mm,
        parameters_mm=float(kappa * np.sqrt(par2)),
        noise_mm=float(vol),
        error_mm=error_mm,
        holdout_mm=float(holdout_mm),
        expected_holdout_mm=float(expected),
        kappa=kappa,
        poses=len(J_train),
        equations=rows,
        parameters=int(J_train.shape[-1]),
    )


def choose_next(J_train: np.ndarray, J_cand: np.ndarray, W: np.ndarray, k: int, taken=()):
    """Indices of k candidates (poses' rows (N, r, P)), chosen one at a time, each the one that
    most reduces tr(W C) given those already measured (J_train) and chosen; `taken` excluded."""
    N = len(J_cand)
    free = np.ones(N, dtype=bool)
    free[list(taken)] = False
    if not 0 < k <= int(free.sum()):
        raise ValueError(f"cannot choose {k} of {int(free.sum())} candidates")
    C = normal_inverse(J_train)
    eye = np.eye(J_cand.shape[1])
    chosen: list[int] = []
    for _ in range(k):
        A = J_cand @ C  # (N, r, P)
        S = eye + np.einsum("nrp,nsp->nrs", A, J_cand)
        # reduction of tr(W C) by pose j: tr(S_j^-1 A_j W A_j')
        B = np.einsum("nrp,pq,nsq->nrs", A, W, A)
        gain = np.einsum("nrr->n", np.linalg.solve(S, B))
        gain[~free] = -np.inf
        j = int(np.argmax(gain))
        chosen.append(j)
        free[j] = False
        Aj = A[j]
        C = C - Aj.T @ np.linalg.solve(S[j], Aj)
    return np.array(chosen)


def decide(pred: Prediction, target_mm: float, poses: int, max_poses: int) -> Decision:
    """The stopping rule: the predicted held-out RMS within the target, or the floor reached
    above the target (more poses would gain under 5 %), or the maximum number of poses."""
    if not target_mm > 0:
        raise ValueError(f"target accuracy must be positive, not {target_mm}")
    if pred.upper_mm <= target_mm and pred.supported:
        return Decision(
            True,
            "target",
            f"predicted held-out RMS {pred.rms_mm:.4f} mm (upper bound {pred.upper_mm:.4f} mm) "
            f"<= target {target_mm:.4f} mm "
            f"after {poses} poses (leave-one-pose-out check x{pred.kappa:.2f} on the parameters' "
            "part)",
        )
    if (
        pred.supported
        and pred.floor_mm * pred.upper_mm / pred.rms_mm > target_mm
        and pred.parameters_mm**2 < FLOOR_SHARE * pred.rms_mm**2
    ):
        return Decision(
            True,
            "floor",
            f"the floor {pred.floor_mm:.4f} mm (a reading's error: the tracker's noise "
            f"{pred.noise_mm:.4f} mm and what the residuals show beyond it) is above the target "
            f"{target_mm:.4f} mm and reached: predicted {pred.rms_mm:.4f} mm after {poses} poses",
        )
    if poses >= max_poses:
        return Decision(
            True,
            "maximum",
            f"maximum of {max_poses} poses reached; predicted held-out RMS {pred.rms_mm:.4f} mm "
            f"> target {target_mm:.4f} mm",
        )
    return Decision(False, "", f"predicted {pred.rms_mm:.4f} mm > target {target_mm:.4f} mm")
