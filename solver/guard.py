"""Whether a fit's data can support its model: held-out error, noise floor, conditioning, size.

The held-out error is leave-one-pose-out cross-validation taken one Gauss-Newton step from the
fit: without pose p the estimating equations G'r = 0 of the other poses move the parameters by
(G'J - G_p'J_p)^-1 G_p'r_p, so pose p's residuals become (I - H_p)^-1 r_p with
H_p = J_p (G'J)^-1 G_p' (Woodbury). Exact for a linear model (the PRESS residuals of least
squares), and the fit's Jacobian is what every refit would start from, so it costs one small
solve per pose instead of a refit. A pose the others cannot do without (I - H_p singular) has no
held-out figure.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .finite import finite
from .uncertainty import Rows, hat_blocks, pose_blocks

# A deployable model has at least this many equations (3 per reading) per free parameter.
MIN_EQUATIONS_PER_PARAMETER = 3
# A fit RMS below this fraction of the tracker's noise floor has absorbed measurement noise, when
# its held-out RMS says so too (more than MAX_HOLDOUT_RATIO x the fit's). A sound least-squares
# fit leaves sqrt(1 - free/equations) of the noise: 0.94 at 30 poses of 3 SMRs and 33 free
# parameters, 0.6 only below 1.6 equations per parameter; with 3 or more (the size limit) a fit
# that far below with its held-out error beside it means the floor is above the readings' noise
# (a floor from the tracker's spec, an MPE that the tracker beats): a warning.
NOISE_FLOOR_FRACTION = 0.6
# Jacobi-scaled condition number of the identification past which the model is not deployed
# (healthy campaigns of 20 poses or more: 10 to 100; identifiability refuses past 1e7).
MAX_CONDITION = 1e3
# A condition number past MAX_CONDITION but within this multiple of the layout's (the same
# parameters' on 240 random poses within the limits) is the robot's and SMRs', not the poses':
# said as a warning, since no poses lower it (a 3 m arm, its SMR 1 mm off the flange axis:
# 1535 on 60 poses, 1551 on 240, the layout's 1311) and the parameters' standard errors and
# the held-out error already say what it costs. Poor poses sit far above their layout's (5
# poses of a 6-axis arm: 1959-4751 against 15.6).
LAYOUT_EXCESS = 2.0
# Held-out RMS more than this multiple of the fit RMS (or of the noise floor, if larger): the
# model does not predict new poses. A sound least-squares fit expects equations / (equations -
# free): 1.14 at 30 poses of 3 SMRs.
MAX_HOLDOUT_RATIO = 2.0
# A model whose held-out RMS exceeds this multiple of the noise floor lacks an effect (a
# diagnosis's `unexplained` block says which covariates the remainder follows): without a
# tolerance not deployable, with one a warning (the tolerance decides). Calibrated and diagnosed
# models alike, so one model gets one verdict from either command.
MAX_FLOOR_RATIO = 3.0
# The smallest singular value of I - H_p below which pose p cannot be held out.
UNSUPPORTED = 1e-9


@dataclass
class Holdout:
    """Leave-one-pose-out residuals of a fit."""

    residuals: np.ndarray  # (N, 3) per reading, NaN for poses that cannot be held out
    unsupported: np.ndarray  # poses the other poses cannot identify the model without

    def rms(self) -> float:
        """3-D RMS per reading (mm) over the poses that can be held out."""
        r = self.residuals[np.all(np.isfinite(self.residuals), axis=1)]
        return float(np.sqrt(np.mean(np.sum(r * r, axis=1)))) if r.size else float("nan")

    def max(self) -> float:
        """Largest held-out reading error (mm)."""
        r = self.residuals
        n = np.linalg.norm(r, axis=1)
        n = n[np.isfinite(n)]
        return float(n.max()) if n.size else float("nan")


@dataclass
class CrossValidated:
    """Held-out figures a cross-validation gave elsewhere (a diagnosis's folds), in mm."""

    rms_mm: float
    max_mm: float
    unsupported: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    def rms(self) -> float:
        return self.rms_mm

    def max(self) -> float:
        return self.max_mm


def leave_one_pose_out(rows: Rows, point: np.ndarray | None = None) -> Holdout:
    """Held-out point errors of every reading, linearised at the fit (see the module's
    docstring). point (N,) bool: the rows that are point errors (predicted - measured, three
    consecutive rows a reading), default all; other rows (ls-pose's pose residuals) only move
    the parameters."""
    out, unsupported = holdout_block(rows, holdout_inverse(rows.G.T @ rows.J))
    point = np.ones(len(out), dtype=bool) if point is None else np.asarray(point, dtype=bool)
    return Holdout(out[point].reshape(-1, 3), np.array(sorted(set(unsupported)), dtype=int))


def holdout_inverse(A: np.ndarray) -> np.ndarray:
    """(G'J)^-1 as the held-out residuals use it: a Jacobi-scaled pseudo-inverse, so a
    rank-deficient fit still gives the poses that can be held out."""
    A = finite(A, "the normal matrix")
    d = np.sqrt(np.abs(np.diag(A)))
    d[d == 0] = 1.0
    return np.linalg.pinv(A / np.outer(d, d)) / np.outer(d, d)


def holdout_block(rows: Rows, Ai: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """Held-out residuals (N,) of rows holding whole poses (NaN where a pose cannot be held
    out) and those poses, given the whole fit's holdout_inverse Ai: each pose's figure depends
    on its own rows and Ai alone, so a fit's rows may be taken a block of poses at a time."""
    out = np.full(len(rows.r), np.nan)
    unsupported: list[int] = []
    for _n, idx in pose_blocks(rows.pose):
        J, G, r = rows.J[idx], rows.G[idx], rows.r[idx]
        out[idx], ok = held_out(hat_blocks(J, G, Ai), r)
        unsupported.extend(rows.pose[idx[~ok, 0]].tolist())
    return out, unsupported


def held_out(H: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(I - H_p)^-1 r_p per pose (H (b, n, n), r (b, n)), NaN for the poses that cannot be held
    out, and which can (b,)."""
    H = finite(H, "the held-out blocks")
    M = np.eye(H.shape[-1]) - H
    # the smallest singular value of I - H is at least 1 - |H|_F: the SVD only where small
    ok = np.sqrt(np.einsum("bij,bij->b", H, H)) < 0.5
    if not ok.all():
        ok[~ok] = np.linalg.svd(M[~ok], compute_uv=False)[:, -1] > UNSUPPORTED
    e = np.full(r.shape, np.nan)
    if ok.any():
        e[ok] = np.linalg.solve(M[ok], r[ok][..., None])[..., 0]
    return e, ok


def strongest_correlations(cov: np.ndarray, k: int = 5) -> list[tuple[int, int, float]]:
    """The k largest |correlation| between distinct parameters of cov: (i, j, r), i < j."""
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    ok = sd > 0
    R = np.zeros_like(cov)
    R[np.ix_(ok, ok)] = cov[np.ix_(ok, ok)] / np.outer(sd[ok], sd[ok])
    i, j = np.triu_indices(len(cov), 1)
    r = np.clip(R[i, j], -1.0, 1.0)
    top = np.argsort(-np.abs(r), kind="stable")[:k]
    return [(int(i[t]), int(j[t]), float(r[t])) for t in top]


@dataclass
class Validation:
    """The guard's verdict on a fit, in mm; reasons are empty when it is deployable."""

    fit_rms_mm: float
    holdout_rms_mm: float
    holdout_max_mm: float
    condition_number: float
    equations: int
    free_parameters: int
    noise_floor_mm: float | None
    unsupported_poses: list = field(default_factory=list)
    reasons: list[str] = field(default_factory=list)
    tolerance_mm: float | None = None  # the accuracy the application needs, None: not given
    warnings: list[str] = field(default_factory=list)  # said beside a verdict they do not decide

    @property
    def deployable(self) -> bool:
        return not self.reasons


def judge(
    *,
    fit_rms_mm: float,
    holdout: Holdout | CrossValidated,
    condition_number: float,
    equations: int,
    free_parameters: int,
    poses: int,
    noise_floor_mm: float | None,
    noise_floor_source: str = "",
    tolerance_mm: float | None = None,
    max_floor_ratio: float | None = MAX_FLOOR_RATIO,
    layout_condition: float | None = None,
    max_fit_mm: float | None = None,
    nominal_holdout_mm: float | None = None,
    explained_share: float | None = None,
) -> Validation:
    """The guard: each limit the fit breaks is one reason, naming its figures and the limit.

    tolerance_mm: the application's accuracy, which the held-out RMS must not exceed;
    max_floor_ratio: the multiple of the noise floor past which the held-out RMS says the model
    lacks an effect, None: not judged; a reason without a tolerance (stating the accuracy to
    expect), a warning with one (the tolerance decides); not said of a fit with too few poses or
    one that does not predict new poses (its held-out excess is its own, not a missing effect's);
    layout_condition: the identified parameters' condition number on rich poses (None: unknown),
    within LAYOUT_EXCESS of which a condition number past the limit is a warning;
    max_fit_mm: the most a right description of the arm errs once calibrated on its own
    readings (solver.plausibility), past which the description, not an effect, is at fault;
    nominal_holdout_mm: the nominal arm's own held-out RMS (its base and SMRs registered, nothing
    of it fitted), None: unknown; a model that predicts new poses worse is never deployable;
    explained_share: the share of the held-out remainder a covariate explains on poses left out
    (a diagnosis's unexplained block), None: not measured; see lacking_effect.
    """
    v = Validation(
        fit_rms_mm,
        holdout.rms(),
        holdout.max(),
        condition_number,
        equations,
        free_parameters,
        noise_floor_mm,
        holdout.unsupported.tolist(),
        tolerance_mm=tolerance_mm,
    )
    need = MIN_EQUATIONS_PER_PARAMETER * free_parameters
    if equations < need:
        per_pose = equations / max(poses, 1)
        v.reasons.append(
            f"too few poses: {poses} poses give {equations} equations (3 per reading) for "
            f"{free_parameters} free parameters, fewer than {MIN_EQUATIONS_PER_PARAMETER} per "
            f"parameter ({need}): measure at least {int(np.ceil(need / max(per_pose, 1)))} poses"
        )
    if noise_floor_mm and fit_rms_mm < NOISE_FLOOR_FRACTION * noise_floor_mm:
        below = (
            f"fit RMS {fit_rms_mm:.4f} mm is below {NOISE_FLOOR_FRACTION:g} x the tracker's "
            f"noise floor {noise_floor_mm:.4f} mm"
            + (f" (from the {noise_floor_source})" if noise_floor_source else "")
        )
        # a fit that absorbed noise predicts new poses worse than it fits them; one whose
        # held-out error stays near its fit says the readings are quieter than the floor (a
        # tracker better than its specification's MPE), which no more poses would change
        if np.isfinite(v.holdout_rms_mm) and v.holdout_rms_mm <= MAX_HOLDOUT_RATIO * fit_rms_mm:
            v.warnings.append(
                f"{below}, and the held-out RMS {v.holdout_rms_mm:.4f} mm with it: the readings "
                "are quieter than that floor (a tracker better than its specification); the "
                "held-out RMS is the accuracy to expect"
            )
        else:
            v.reasons.append(f"{below}: the fit absorbed measurement noise")
    if np.isnan(condition_number):
        v.reasons.append(
            "the condition number is not a figure: nothing of the arm was identified (the "
            "nominal model, only registered on the data), or its identification failed"
        )
    elif not condition_number <= MAX_CONDITION and _layouts(condition_number, layout_condition):
        v.warnings.append(
            f"condition number {condition_number:.3g} exceeds {MAX_CONDITION:.0f}, as the robot "
            f"and SMR layout's own ({layout_condition:.3g} on random poses within the limits): "
            "more poses would not lower it; the parameters it barely separates are as well "
            "known as their standard errors say (SMRs further from the joint axes separate them)"
        )
    elif not condition_number <= MAX_CONDITION:
        v.reasons.append(
            f"condition number {condition_number:.3g} exceeds {MAX_CONDITION:.0f}: the poses "
            "barely separate some parameters; measure more poses, spread over the joint ranges"
        )
    if len(holdout.unsupported):
        v.reasons.append(
            f"{len(holdout.unsupported)} of {poses} poses cannot be held out: without any one of "
            "them the other poses cannot identify the model"
        )
    # against the fit RMS, or the noise floor where the fit went below it: a held-out error
    # near the tracker's noise is as good as any model predicts, however small the fit's
    ref = max(fit_rms_mm, noise_floor_mm or 0.0)
    ratio = v.holdout_rms_mm / ref if ref > 0 else float("inf")
    overfit = np.isfinite(v.holdout_rms_mm) and not ratio <= MAX_HOLDOUT_RATIO
    if overfit:
        v.reasons.append(
            f"held-out RMS {v.holdout_rms_mm:.4g} mm is {ratio:.3g} x the "
            + (
                f"fit RMS {fit_rms_mm:.4f} mm"
                if ref == fit_rms_mm
                else f"noise floor {ref:.4f} mm (the fit RMS {fit_rms_mm:.4f} mm is below it)"
            )
            + f" (limit {MAX_HOLDOUT_RATIO:g} x): the model does not predict poses it was not "
            "fitted on"
        )
    v.reasons += beyond_tolerance(v.holdout_rms_mm, tolerance_mm)
    v.warnings += max_beyond_tolerance(v.holdout_rms_mm, v.holdout_max_mm, tolerance_mm)
    v.warnings += below_noise(tolerance_mm, noise_floor_mm, noise_floor_source)
    v.reasons += worse_than_nominal(v.holdout_rms_mm, nominal_holdout_mm)
    wrong_arm = max_fit_mm is not None and not fit_rms_mm <= max_fit_mm
    if wrong_arm:
        v.reasons.append(
            f"the calibrated model errs {fit_rms_mm:.4g} mm RMS on the readings it was fitted on "
            f"(more than the {max_fit_mm:.3g} mm any calibration of a right description of this "
            "arm leaves): the cell's robot is not the arm measured (a twist's or a joint's sign, "
            "a joint offset convention, another robot) or the tracker moved during the campaign"
        )
    # else the excess is the fit's or the description's, said above
    if not overfit and not wrong_arm and equations >= need:
        lacking = lacking_effect(v, max_floor_ratio, explained_share)
        if tolerance_mm is None:
            v.reasons += lacking
        else:
            v.warnings += lacking
    return v


def beyond_tolerance(holdout_rms_mm: float, tolerance_mm: float | None) -> list[str]:
    """The reason a held-out error beyond the application's tolerance gives (none within)."""
    if tolerance_mm is None:
        return []
    if not np.isfinite(holdout_rms_mm):
        return [
            f"the held-out error is unknown (no pose could be held out): it cannot be judged "
            f"against the tolerance {tolerance_mm:g} mm"
        ]
    if holdout_rms_mm <= tolerance_mm:
        return []
    # three digits, more where they would print the tolerance itself (0.30004 beyond 0.3)
    digits = next((n for n in range(3, 8) if float(f"{holdout_rms_mm:.{n}g}") > tolerance_mm), 8)
    return [
        f"held-out error {holdout_rms_mm:.{digits}g} mm RMS exceeds the tolerance "
        f"{tolerance_mm:g} mm"
    ]


def max_beyond_tolerance(
    holdout_rms_mm: float, holdout_max_mm: float, tolerance_mm: float | None
) -> list[str]:
    """The warning a held-out RMS within the tolerance gives when the worst held-out reading is
    beyond it: the verdict judges the RMS, the application may need every point."""
    if tolerance_mm is None or not holdout_rms_mm <= tolerance_mm < holdout_max_mm:
        return []
    return [
        f"the held-out RMS {holdout_rms_mm:.3g} mm is within the tolerance {tolerance_mm:g} mm, "
        f"but the worst held-out reading misses by {holdout_max_mm:.3g} mm: some new poses will "
        "be beyond it"
    ]


def below_noise(
    tolerance_mm: float | None, noise_floor_mm: float | None, source: str = ""
) -> list[str]:
    """The warning a tolerance below the readings' noise floor gives (none otherwise): no
    held-out error can be shown below the noise of the readings it is measured with."""
    if tolerance_mm is None or not noise_floor_mm or not tolerance_mm < noise_floor_mm:
        return []
    # a tolerance in metres is a thousandth of its figure in mm (0.0005 for 0.5 mm)
    metres = 1000 * tolerance_mm >= noise_floor_mm
    return [
        f"the tolerance {tolerance_mm:g} mm is below the readings' noise floor "
        f"{noise_floor_mm:.4f} mm" + (f" (from the {source})" if source else "") + ": no model "
        "can be shown to meet it"
        + (
            f" (metres typed for mm? {tolerance_mm:g} m is {1000 * tolerance_mm:g} mm)"
            if metres
            else ""
        )
    ]


def worse_than_nominal(holdout_rms_mm: float, nominal_holdout_mm: float | None) -> list[str]:
    """The reason a model that predicts new poses worse than the nominal arm gives (none when
    it does not, or when either figure is unknown)."""
    if nominal_holdout_mm is None or not np.isfinite(nominal_holdout_mm):
        return []
    if not np.isfinite(holdout_rms_mm) or holdout_rms_mm <= nominal_holdout_mm:
        return []
    return [
        f"held-out error {holdout_rms_mm:.4g} mm RMS exceeds the nominal model's own "
        f"{nominal_holdout_mm:.4g} mm (held out alike; its base and SMRs registered, nothing of "
        "the arm fitted): the calibration makes the arm less accurate than its nominal "
        "description (too few or too noisy poses for the parameters fitted, or a wrong "
        "description)"
    ]


def lacking_effect(
    v: Validation, max_floor_ratio: float | None, explained_share: float | None = None
) -> list[str]:
    """What a held-out error far above the noise floor says: the model lacks an effect; without
    a tolerance, the accuracy to expect and how to judge it against the application's need.

    explained_share s: the share of the held-out remainder a covariate explains on poses left
    out; noise, which nothing predicts, holds at most the rest, rms sqrt(1 - s). Far below a
    stated floor (a tracker spec's MPE, which the readings may beat) that bound is the data's
    own word: the remainder is judged against it too."""
    rms, floor = v.holdout_rms_mm, v.noise_floor_mm
    if not max_floor_ratio or not floor or not np.isfinite(rms):
        return []
    ratio = rms / floor
    share = explained_share or 0.0
    room = rms * np.sqrt(max(1.0 - share, 0.0)) if share else floor
    if ratio > max_floor_ratio:
        said = (
            f"held-out error {rms:.3g} mm is {ratio:.3g}x the noise floor {floor:.3f} mm (more "
            f"than {max_floor_ratio:g}x): an effect the model lacks (a diagnosis's unexplained "
            "block says what the remainder follows)"
        )
    elif room < floor and rms > max_floor_ratio * room:
        said = (
            f"held-out error {rms:.3g} mm is within {max_floor_ratio:g}x the stated noise floor "
            f"{floor:.3f} mm, but {100 * share:.0f}% of it follows a covariate on poses "
            f"left out (the diagnosis's unexplained block), which leaves noise at most "
            f"{room:.3g} mm, {rms / room:.3g}x less: the floor overstates the readings' noise "
            "and the model lacks an effect"
        )
    else:
        return []
    if v.tolerance_mm is not None:
        return [said]
    return [
        f"{said}; expect {rms:.3g} mm RMS, max {v.holdout_max_mm:.3g} mm on new poses: give the "
        "tolerance the application needs (--tolerance-mm, or the cell's tolerance_mm) to deploy "
        "within it"
    ]


def _layouts(condition: float, layout: float | None) -> bool:
    """Whether a condition number is within LAYOUT_EXCESS of its layout's (the poses' no fault)."""
    return layout is not None and np.isfinite(layout) and condition <= LAYOUT_EXCESS * layout
