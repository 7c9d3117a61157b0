"""Whether the model's extensions hold beyond the poses they were fitted on.

Random folds test a model on poses among its training poses; a user's later poses lie elsewhere:
in another elbow or wrist configuration, another part of the joint space. Region folds split the
campaign at the median of a gravity-loaded joint (of any other joint, for that joint's own
effects: own folds), and configuration folds by the arm's configuration (elbow, wrist) where the
campaign has poses in both: train on
one side, test on the other, so an effect that only fitted the quirks of one region shows up as
a worse test than geometry's there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import configuration
from .gravity import gravity_in_base
from .kinematics import Layout, joint_frames, predict
from .report_blocks import ExtrapolationReport, FoldResult, Refused
from .tall import tall_svd

# A joint is gravity-loaded when its axis is on average this far from vertical (|cos| below).
HORIZONTAL_AXIS = 0.7
# Joints that move less than this (rad) over the campaign give no region to extrapolate to.
MIN_SPAN_RAD = np.radians(10.0)
# A joint whose axis passes closer than this (mm) to every SMR does not move the readings.
MIN_LEVER_MM = 1.0
# An extension is refused when a region fold's held-out RMS exceeds geometry's by this factor.
MAX_RATIO = 1.02
# A region fold tests at least this many poses.
MIN_TEST_POSES = 5
# A configuration fold trains on a side with at least this share of the poses.
MIN_TRAIN_SHARE = 1 / 3
# The configuration bits (solver.configuration's cfx) a fold may split by, and each side's name.
CONFIGURATIONS = (
    (
        "elbow",
        configuration.BEHIND_LOWER_ARM,
        "wrist centre behind the lower arm",
        "wrist centre in front of the lower arm",
    ),
    ("wrist", configuration.JOINT5_NEGATIVE, "q5 < 0", "q5 >= 0"),
)


@dataclass(frozen=True)
class RegionFold:
    """Test poses on one side of a joint's median (or in one arm configuration), the training
    poses on the other."""

    joint: int  # 0-based: the split's joint (configuration folds: the one reaching furthest)
    at_rad: float
    above: bool  # the test poses are those at or above the split
    test: np.ndarray  # pose indices
    beyond_rad: float  # how far the test poses reach past the training poses' range
    configuration: str | None = None  # configuration folds: the test poses' configuration
    own: bool = False  # judges only the effects of its joint (a joint gravity does not load)

    def label(self) -> str:
        if self.configuration is not None:
            return self.configuration
        side = ">=" if self.above else "<="
        return f"q{self.joint + 1} {side} {np.degrees(self.at_rad):.1f} deg"


@dataclass(frozen=True)
class SpanParts:
    """A test residual's sum of squares (mm^2) inside and outside the span of the test poses'
    geometric Jacobian: what a geometric refit there could remove, and what none could."""

    inside: float
    outside: float


@dataclass(frozen=True)
class FoldCheck:
    """One region fold: the geometric and the extended model's held-out RMS (mm) there; where
    measured, their test residuals split by the test poses' geometric span, and the part inside it
    of the extended model's move from geometry's prediction (sum of squares, mm^2)."""

    fold: RegionFold
    geometric_rms: float
    extended_rms: float
    geometric_parts: SpanParts | None = None
    extended_parts: SpanParts | None = None
    shift_inside: float | None = None

    @property
    def worse(self) -> bool:
        return self.extended_rms > MAX_RATIO * self.geometric_rms and not self.geometry_to_blame

    @property
    def geometry_to_blame(self) -> bool:
        """The extended model's excess lies in the geometric span: outside it (the effect's own
        part, which no geometric refit explains) it is no worse than geometry; its move of the
        prediction inside it (its geometric parameters, fitted beside the effect on one region,
        extrapolating otherwise) stays below geometry's own error there plus what the effect
        gained outside; and each part judged against geometry's own on it, the effect's relative
        gain outside outweighs its relative loss inside (the product of the two ratios below 1).
        A fold trained on half a campaign extrapolates geometry poorly whatever the model; that
        alone refused true effects that removed most of geometry's excess in the other
        configuration (a backlash fitted on 20 poses). Without the last condition, periodic terms
        on a real UR5 that gained 7% outside the span and lost 180% inside it passed, and tested
        2.3x geometry's error on the other half of the campaign."""
        g, e = self.geometric_parts, self.extended_parts
        if g is None or e is None or self.shift_inside is None:
            return False
        gain = g.outside - e.outside
        if gain < 0 or self.shift_inside >= g.inside + gain:
            return False
        return e.outside * e.inside < g.outside * g.inside


def span_parts(Jt: np.ndarray, r: np.ndarray) -> SpanParts | None:
    """r's sum of squares inside and outside the column span of J (Jt (P, N, 3), r (N, 3));
    None when the span leaves less room outside it than it takes (fewer rows than twice its
    independent columns): a few dimensions outside it would judge the effect by chance."""
    J = Jt.reshape(Jt.shape[0], -1).T
    y = r.ravel()
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(y))):
        return None
    U, s = tall_svd(J)
    rank = int(np.sum(s > s[0] * max(J.shape) * np.finfo(float).eps)) if s.size else 0
    if J.shape[0] - rank < rank:
        return None
    inside = float(np.sum((U[:, :rank].T @ y) ** 2))
    return SpanParts(inside, max(float(y @ y) - inside, 0.0))


def gravity_loaded(layout: Layout, x, q: np.ndarray) -> list[int]:
    """Joints whose axes lie mostly horizontal over the campaign (the levelled tracker's z up)."""
    frames = joint_frames(Layout(layout.robot, np.eye(4), layout.target_names), x, q)
    g = gravity_in_base(layout, x)
    return [
        j
        for j, (R, _) in enumerate(frames[: layout.robot.n_joints])
        if float(np.mean(np.abs(R[:, :, 2] @ g))) < HORIZONTAL_AXIS
    ]


def more_than_a_turn(robot) -> np.ndarray:
    """Per joint, whether its limits hold more than a turn (a wrist's +-400 deg)."""
    return robot.upper - robot.lower > 2 * np.pi


def beyond(test: np.ndarray, train: np.ndarray, turns: bool = False) -> float:
    """How far (rad) the test angles reach outside the training angles' range; on a joint that
    turns, on the circle: -355 deg is where 5 deg is. That holds for the kinematics only (a
    cable-wound joint, or an effect in the joint's own angle such as a scale error, is another
    arm a turn further), so it serves the distance figure the report shows, never a judgement."""
    lo, hi = float(train.min()), float(train.max())
    if not turns:
        return max(float(test.max()) - hi, lo - float(test.min()), 0.0)
    span, turn = hi - lo, 2 * np.pi
    if span >= turn:
        return 0.0
    d = np.mod(test - lo, turn)  # where each test angle lies a turn from the range's start
    return float(np.max(np.where(d <= span, 0.0, np.minimum(d - span, turn - d))))


def region_folds(layout: Layout, x, q: np.ndarray, min_poses: int) -> list[RegionFold]:
    """Both ends of each gravity-loaded joint that moves: the poses above (below) its median
    tested, the others trained on. A campaign too small to fit on half of it tests a smaller end
    (at least MIN_TEST_POSES poses) and trains on the min_poses others: without that, a small
    campaign's effects went untested off their poses (on 18 real poses a periodic term doubled
    the error on the other half). An arm gravity loads no joint of (a SCARA: every axis
    vertical) splits at every joint's median instead: it had no fold at all, and its effects
    (a joint's periodic error, backlash) went untested off their poses, said as 'too few poses
    to split' on 40 poses where 36 of an IRB 120 gave 10 folds."""
    turns = more_than_a_turn(layout.robot)
    return joint_folds(q, min_poses, split_joints(layout, x, q), turns=turns)


def split_joints(layout: Layout, x, q: np.ndarray) -> list[int]:
    """The joints region folds split at: the gravity-loaded ones, else those moving an SMR."""
    return gravity_loaded(layout, x, q) or moving_smrs(layout, x, q)


def moving_smrs(layout: Layout, x, q: np.ndarray) -> list[int]:
    """Joints whose axis passes at least MIN_LEVER_MM from an SMR: the others (a SCARA's last
    joints turning one SMR on their axis) split the campaign at random as far as the readings
    go, and their reach 'beyond the training poses' would be no distance at all."""
    frames = joint_frames(layout, x, q)
    smr = predict(layout, x, q)  # (m, K, 3)
    out = []
    for j, (R, o) in enumerate(frames[: layout.robot.n_joints]):
        lever = np.cross(smr - o[:, None, :], R[:, None, :, 2])
        if float(np.max(np.linalg.norm(lever, axis=-1))) >= MIN_LEVER_MM:
            out.append(j)
    return out


def joint_folds(
    q: np.ndarray, min_poses: int, joints, own: bool = False, turns=None
) -> list[RegionFold]:
    """Both ends of each of the joints that moves (region_folds); own: folds that judge only
    the effects of their joint; turns (per joint, more_than_a_turn): whose reach beyond the
    training poses is measured on the circle."""
    m = q.shape[0]
    n_test = min(m // 2, m - min_poses)
    if n_test < MIN_TEST_POSES:
        return []
    out = []
    for j in joints:
        qj = q[:, j]
        if np.ptp(qj) < MIN_SPAN_RAD:
            continue
        order = np.argsort(qj, kind="stable")
        for above in (False, True):
            test = np.sort(order[m - n_test :] if above else order[:n_test])
            train = np.setdiff1d(np.arange(m), test)
            at = float(qj[test].min() if above else qj[test].max())
            far = beyond(qj[test], qj[train], turns is not None and bool(turns[j]))
            out.append(RegionFold(j, at, above, test, far, own=own))
    return out


def configuration_folds(robot, q: np.ndarray, min_poses: int) -> list[RegionFold]:
    """Trained in one elbow (wrist) configuration, tested in the other, for each
    configuration bit the campaign's poses differ in: each side with at least min_poses poses,
    and trained only on a side with at least a third of the poses (fewer test how a fit on few
    poses extrapolates, not the effect: a true backlash fitted on a quarter of a campaign missed
    the rest by more than geometry did)."""
    if not configuration.supports(robot):
        return []
    bits = configuration.cfx(robot, q)
    turns = more_than_a_turn(robot)
    out = []
    for name, bit, set_side, clear_side in CONFIGURATIONS:
        side = (bits & bit) > 0
        if min(side.sum(), (~side).sum()) < min_poses:
            continue
        for tested, label in ((True, set_side), (False, clear_side)):
            test = np.flatnonzero(side == tested)
            train = q[side != tested]
            if len(train) < max(min_poses, MIN_TRAIN_SHARE * len(q)):
                continue
            reach = [beyond(q[test, j], train[:, j], t) for j, t in enumerate(turns)]
            j = int(np.argmax(reach))
            out.append(RegionFold(j, float("nan"), tested, test, reach[j], f"{name}: {label}"))
    return out


def fold_poses(diag) -> int:
    """Poses enough to fit on one side of a fold of a diagnosis (solver.diagnose.Diagnoser): its
    free parameters over the SMRs a pose (the prior, not the data, pins the shrunk ones)."""
    per_pose = max(1, int(diag.prob.mask.any(axis=0).sum()))  # SMRs a pose
    return int(np.ceil((diag.free & ~diag.shrunk).sum() / per_pose)) + 1


def joint_ranges(q: np.ndarray) -> np.ndarray:
    """(n, 2) the joint-space box the campaign covers, rad: where the model may be trusted."""
    return np.stack([q.min(axis=0), q.max(axis=0)], axis=1)


def extrapolation_report(checks, refused, q) -> ExtrapolationReport:
    """The report's `extrapolation` block: how far from its training poses the model was tested
    (checks: the folds' FoldCheck), the effects refused there (refused: (extension, the
    checks it failed)), and the joint-space box the data covers (where it may be trusted)."""

    def num(v):
        return None if not np.isfinite(v) else float(v)

    return ExtrapolationReport(
        method="train on one side of a gravity-loaded joint's median (of any joint where gravity "
        "loads none; of any other joint for that joint's own effects; a smaller end on a small "
        "campaign), or in one elbow or wrist configuration where the data has both, test "
        "on the other",
        max_ratio_to_geometric=MAX_RATIO,
        folds=[
            FoldResult(
                test=c.fold.label(),
                test_poses=len(c.fold.test),
                beyond_training_deg=float(np.degrees(c.fold.beyond_rad)),
                geometric_rmse_mm=num(c.geometric_rms),
                final_rmse_mm=num(c.extended_rms),
                worse_only_in_geometric_span=c.extended_rms > MAX_RATIO * c.geometric_rms
                and c.geometry_to_blame,
            )
            for c in checks
        ],
        refused=[
            Refused(
                name=e.name,
                label=e.label(),
                joint=None if e.joint is None else e.joint + 1,
                worse_on=_worse_on(bad),
                reason="; ".join([c for c in bad if isinstance(c, str)])
                or "worse than geometry on " + "; ".join(_worse_on(bad)),
            )
            for e, bad in refused
        ],
        joint_range_deg=np.degrees(joint_ranges(q)).round(3).tolist(),
    )


def _worse_on(bad) -> list[str]:
    """The folds among an effect's refusals (FoldCheck, or a sentence why), in a phrase each."""
    return [
        f"{c.fold.label()}: {c.extended_rms:.4f} mm vs geometric {c.geometric_rms:.4f}"
        for c in bad
        if not isinstance(c, str)
    ]
