"""The structural identifiability check a block of poses at a time gives what the whole
Jacobian gave (the code before issue 20, kept here as the reference), in memory linear in the SMRs."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.solver import identifiability as ident
from robocal.solver.identify import pose_residuals
from robocal.solver.kinematics import Layout, predict_with_jacobian
from robocal.solver.robot import IRB2600, KUKA_LIKE, robot_from_degrees
from tests.sim import peak_mb, smr_ring

SEVEN = robot_from_degrees(
    "seven",
    "dh",
    [
        (150.0, 445.0, 0.0, -90.0, (-170.0, 170.0)),
        (900.0, 0.0, -90.0, 0.0, (-95.0, 155.0)),
        (150.0, 0.0, 0.0, -90.0, (-170.0, 75.0)),
        (0.0, 400.0, 0.0, 90.0, (-170.0, 170.0)),
        (0.0, 538.0, 0.0, -90.0, (-170.0, 170.0)),
        (0.0, 0.0, 0.0, 90.0, (-120.0, 120.0)),
        (0.0, 200.0, 0.0, 0.0, (-170.0, 170.0)),
    ],
)


def whole_jacobian(robot, targets, candidates, rows=None, weight=None):
    """The pre-issue-20 _structural: one QR of the whole (poses x SMRs x 3, P) Jacobian."""
    names = tuple(f"T{i}" for i in range(len(targets)))
    layout = Layout(robot, np.eye(4), names)
    x = layout.initial(np.round(targets, 3))
    rows = list(range(len(targets))) if rows is None else list(rows)
    rng = np.random.default_rng(0)
    q = rng.uniform(robot.lower, robot.upper, size=(ident.STRUCTURAL_POSES, robot.n_joints))
    p, J, _ = predict_with_jacobian(layout, x, q)
    if weight is None:
        J = J[:, rows].reshape(-1, layout.n_params)
    else:
        J = pose_residuals(p, p, J, weight)[1].reshape(-1, layout.n_params)
    R = np.linalg.qr(J, mode="r")
    kept = ident.choose_free(R, ident.preference_order(layout), candidates, ident.STRUCTURAL_TOL)
    n = layout.names()
    fixed = {n[j]: ident._explain(R, int(j), kept, n) for j in np.flatnonzero(candidates & ~kept)}
    return layout, kept, fixed, ident.condition_number(J[:, kept])


@pytest.mark.parametrize(
    ("robot", "k", "rows", "weight"),
    [
        (IRB2600, 3, None, None),
        (IRB2600, 1, None, None),
        (IRB2600, 3, (1,), None),  # ls-single:B
        (IRB2600, 3, None, 500.0),  # ls-pose
        (KUKA_LIKE, 5, None, None),
        (SEVEN, 4, None, None),
    ],
    ids=["irb2600-3", "irb2600-1", "single", "pose", "kuka-5", "seven-4"],
)
def test_blockwise_structural_check_equals_the_whole_jacobians(robot, k, rows, weight):
    targets = smr_ring(k)
    layout = Layout(robot, np.eye(4), tuple(f"T{i}" for i in range(k)))
    candidates = np.ones(layout.n_params, dtype=bool)
    ts = layout.target_slice.start
    for i in set(range(k)) - set(range(k) if rows is None else rows):
        candidates[ts + 3 * i : ts + 3 * i + 3] = False  # as calibrate() holds unmeasured SMRs
    _, kept, fixed, cond = whole_jacobian(robot, targets, candidates, rows, weight)
    ident._structural.cache_clear()
    st = ident.structural(
        layout, layout.initial(targets), candidates, rows=rows, pose_weight=weight
    )
    np.testing.assert_array_equal(st.free, kept)
    assert st.fixed == fixed
    assert st.condition == pytest.approx(cond, rel=1e-9)


def test_the_structural_checks_memory_grows_linearly_with_the_smrs():
    # deterministic (the same arrays every run), so a fair bound: 16 SMRs carry 16/3 the
    # parameters of 3, so a linear check needs under 16/3 the memory; the whole Jacobian
    # needed about (16/3)^2 (8x measured before issue 20)
    def check(k):
        ident._structural.cache_clear()
        ident._rich_r.cache_clear()  # the rich poses' R it is built on, cached apart
        names = tuple(f"T{i}" for i in range(k))
        layout = Layout(IRB2600, np.eye(4), names)
        return lambda: ident.structural(
            layout, layout.initial(smr_ring(k)), np.ones(layout.n_params, dtype=bool)
        )

    three, sixteen = peak_mb(check(3)), peak_mb(check(16))
    print(f"structural check peak: 3 SMRs {three:.2f} MiB, 16 SMRs {sixteen:.2f} MiB")
    assert sixteen < 16 / 3 * three
