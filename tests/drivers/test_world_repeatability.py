"""The simulated arm returns to a pose as its data sheet's repeatability says: the SMRs' positions
over many returns scatter with that RP (ISO 9283: l_bar + 3 S_l about their barycentre), the
same for every SMR and drawn afresh at each move; without a repeatability it returns exactly."""

from __future__ import annotations

import numpy as np

from robocal.drivers.cell import VirtualCell
from robocal.drivers.clock import VirtualClock
from robocal.drivers.world import SimulatedWorld
from robocal.solver.repeatability import rp_of
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS

RETURNS = 4000


def returns(repeatability_mm: float) -> np.ndarray:
    """SMR positions (RETURNS, K, 3) each time the arm comes back to one pose from another."""
    vc = VirtualCell.random(IRB2600, TARGETS, seed=2)
    clock = VirtualClock()
    world = SimulatedWorld(vc, clock, repeatability_mm=repeatability_mm)
    here, away = vc.sample_poses(2, np.random.default_rng(4))
    out = []
    for _ in range(RETURNS):
        for q in (away, here):
            clock.sleep(world.command_move(q))
        out.append(world.smr_positions())
    return np.array(out)


def test_the_arm_scatters_about_a_pose_with_its_stated_rp():
    p = returns(0.04)
    rp = rp_of(np.moveaxis(p, 1, 0))  # per SMR
    print(f"\nRP over {RETURNS} returns, per SMR (mm): {np.round(rp, 4)}")
    assert np.allclose(rp, 0.04, rtol=0.04), rp
    moved = p - p.mean(axis=0)
    assert np.allclose(moved[:, 0], moved[:, 1])  # a rigid shift: the SMRs alike


def test_without_a_repeatability_the_arm_returns_exactly():
    p = returns(0.0)
    assert np.ptp(p, axis=0).max() < 1e-9
