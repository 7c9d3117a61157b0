"""Extensions that hold off the training poses (issue 21, points 2 and 3): the real IRB 120 split
six ways, region folds, and an extension that fits one region's quirks refused."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.solver.extrapolation import (
    FoldCheck,
    RegionFold,
    SpanParts,
    span_parts,
)


def rms(pred, meas) -> float:
    e2 = np.sum((pred - meas) ** 2, axis=-1)
    return float(np.sqrt(np.nanmean(e2)))


def test_span_parts_split_a_residual_by_the_geometric_jacobian():
    rng = np.random.default_rng(3)
    Jt = rng.normal(size=(4, 10, 3))  # 4 parameters, 10 readings
    J = Jt.reshape(4, -1).T
    inside = J @ rng.normal(size=4)
    noise = rng.normal(size=30)
    outside = noise - J @ np.linalg.lstsq(J, noise, rcond=None)[0]
    parts = span_parts(Jt, (inside + outside).reshape(10, 3))
    assert parts is not None
    assert parts.inside == pytest.approx(inside @ inside)
    assert parts.outside == pytest.approx(outside @ outside)
    # as many independent columns as rows: nothing lies outside, nothing to judge by; fewer
    # dimensions outside the span than in it: too few to judge by either
    assert span_parts(rng.normal(size=(6, 2, 3)), rng.normal(size=(2, 3))) is None
    assert span_parts(rng.normal(size=(4, 2, 3)), rng.normal(size=(2, 3))) is None
    assert span_parts(rng.normal(size=(3, 2, 3)), rng.normal(size=(2, 3))) is not None
    assert span_parts(Jt, np.full((10, 3), np.nan)) is None


def check(extended_rms, g, e, shift, geometric_rms=0.10):
    fold = RegionFold(1, 0.0, True, np.arange(20), 0.5)
    return FoldCheck(fold, geometric_rms, extended_rms, SpanParts(*g), e and SpanParts(*e), shift)


def test_a_fold_worse_only_inside_the_geometric_span_blames_geometry():
    """Worse than geometry on a fold by its in-span part (geometric parameters extrapolating from
    one region) while better outside it: not the effect's fault. Worse outside the span, or moving
    the in-span prediction by more than geometry misses there, or unmeasured: refused as before."""
    # inside 0.18 -> 0.45 mm^2, outside 0.22 -> 0.03: a true effect fitted on half the poses
    assert not check(0.11, (0.18, 0.22), (0.45, 0.03), 0.08).worse
    assert check(0.11, (0.18, 0.22), (0.45, 0.03), 0.08).geometry_to_blame
    assert check(0.11, (0.18, 0.22), (0.20, 0.30), 0.01).worse  # the effect's part is worse
    # moved inside more than geometry misses there, but less than that and the gain outside
    assert not check(0.11, (0.18, 0.22), (0.45, 0.03), 0.30).worse
    assert check(0.11, (0.18, 0.22), (0.45, 0.03), 0.40).worse  # more than both
    # the real UR5's periodic terms: 7% better outside the span, 2.8x worse inside it (moved
    # there by half geometry's error): the relative loss outweighs the gain, refused
    assert check(0.354, (10.37, 2.256), (29.23, 2.094), 5.287, geometric_rms=0.2247).worse
    assert check(0.11, (0.18, 0.22), None, None).worse  # no span measured
    assert not check(0.101, (0.18, 0.22), (0.9, 0.9), 0.9).worse  # within 1.02x: never refused


def test_a_joint_of_more_than_a_turn_reaches_beyond_its_training_poses_on_the_circle():
    """The IRB 2600's q6 (+-400 deg) trained at 5..20 deg and tested at -355..-340 deg: the same
    arm positions, not 360 deg beyond them; the fold's figure is q5's 40 deg. A joint whose
    limits hold less than a turn keeps the straight distance."""
    from robocal.solver.extrapolation import configuration_folds, joint_folds
    from robocal.solver.robot import IRB2600

    m = 20
    q = np.zeros((m, 6))
    q[:, 1], q[:, 2] = np.radians(10.0), np.radians(-20.0)
    neg = np.arange(m) < m // 2
    q[:, 4] = np.radians(np.where(neg, -30.0, 10.0) + np.tile(np.linspace(0, 20, m // 2), 2))
    q[:, 5] = np.radians(np.where(neg, -355.0, 5.0) + np.tile(np.linspace(0, 15, m // 2), 2))
    folds = {f.label(): f for f in configuration_folds(IRB2600, q, 5)}
    fold = folds["wrist: q5 < 0"]
    assert fold.joint == 4 and np.degrees(fold.beyond_rad) == pytest.approx(40.0)
    # a region fold across q6 itself: trained at the lower end, tested a turn from it
    turns = IRB2600.upper - IRB2600.lower > 2 * np.pi
    below = [f for f in joint_folds(q, 5, [5], turns=turns) if not f.above]
    assert np.degrees(below[0].beyond_rad) == pytest.approx(0.0, abs=1e-9)
    straight = [f for f in joint_folds(q, 5, [5]) if not f.above]
    assert np.degrees(straight[0].beyond_rad) == pytest.approx(360.0)
