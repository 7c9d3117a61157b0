"""solver.lookalike's look-alike cross-validations leave the diagnoser as they found it (its warm
starts were cleared as a hidden side effect), and beyond's moved copies keep each pose's inputs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from robocal.solver import lookalike
from robocal.solver.calibrate import calibrate
from robocal.solver.diagnose import Diagnoser, candidates
from robocal.solver.identify import register
from robocal.solver.vocabulary import Inputs
from tests.server.test_lookalike_held import one_smr_half_range


def _diagnoser(seed: int, spec: str):
    """As solver.diagnose sets one up, on a half-range 30-pose one-SMR campaign."""
    case, meas, nominal, train, _ = one_smr_half_range(seed, spec)
    from robocal.solver.problem import Problem

    p = Problem.of(case.robot, nominal, meas.subset(train))
    prob, x0 = register(p.robot, p.targets, p.target_names, p.q, p.meas, p.base_guess)
    geo = calibrate(replace(p, noise_floor_mm=0.01), "ls-sum")
    free = np.array([n not in geo.fixed for n in prob.layout.names()])
    shrunk = np.isin(prob.layout.names(), list(geo.shrunk))
    start = prob.layout.expressed(geo.layout, geo.x)
    inputs = p.inputs()
    diag = Diagnoser(prob, x0, free, inputs, prior=geo.prior, shrunk=shrunk, start=start)
    return diag, candidates(prob.layout, x0, inputs)


def test_holding_look_alikes_leaves_the_warm_starts_as_they_were():
    """Joint 3's first harmonic fitted on half its range (the case test_lookalike_held holds):
    its look-alikes are cross-validated from geometry, and the diagnoser's warm starts (the
    final model's fits, as the selection leaves them) are still there afterwards."""
    diag, cands = _diagnoser(7, "joint_periodic:3:2=0.016653")
    periodic = next(
        c for c in cands if c.name == "joint_periodic" and c.joint == 2 and c.harmonic == 1
    )
    final = diag.cross_validate([periodic])
    diag.warm = warm = final.fits
    x, ee = final.fits["all"]
    out, held = lookalike.hold_lookalikes(diag, final, x, ee, cands)
    print("\nheld:", [h.sentence() for h in held])
    assert held and out[0].held is not None  # look-alikes were cross-validated and parted
    assert diag.warm is warm, "hold_lookalikes changed the diagnoser's warm starts"
    diag.warm = {}  # the same answer from a diagnoser without warm starts
    again, held_cold = lookalike.hold_lookalikes(diag, final, x, ee, cands)
    assert held_cold == held and np.allclose(again[0].held, out[0].held)


def test_beyond_moves_the_joint_and_keeps_each_poses_inputs():
    q = np.radians([[0.0, 10.0, 5.0], [0.0, 20.0, -5.0]])
    time_s, temp_c = np.array([[1.0], [2.0]]), np.array([[20.0], [21.0]])
    moved = lookalike.beyond(
        Inputs(q, time_s, temp_c), 1, q[:, 1].min(), q[:, 1].max(), np.radians([-90.0, 90.0])
    )
    copies = len(moved.q) // len(q)
    assert copies == 2 * len(lookalike.STEPS) and len(moved.q) == copies * len(q)
    assert np.allclose(moved.time_s, np.tile(time_s, (copies, 1)))
    assert np.allclose(moved.temp_c, np.tile(temp_c, (copies, 1)))
    assert np.array_equal(moved.motion, np.tile(Inputs(q).motion, (copies, 1)))
    assert np.allclose(moved.q[:, [0, 2]], np.tile(q[:, [0, 2]], (copies, 1)))
    assert not np.any((moved.q[:, 1] > q[:, 1].min()) & (moved.q[:, 1] < q[:, 1].max()))
