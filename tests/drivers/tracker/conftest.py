"""An IRB 2600 cell with its simulated tracker, at a valid pose, on a virtual clock."""

from types import SimpleNamespace

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.clock import VirtualClock
from robocal.drivers.tracker.sim import SimulatedTracker
from robocal.drivers.world import SimulatedWorld
from robocal.solver.robot import IRB2600

TARGETS = {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]}


def make_rig(seed: int = 1, settled: bool = True, **tracker_kw) -> SimpleNamespace:
    """Cell, clock, world and tracker; settled: the arm arrived long ago (no ringing)."""
    cell = VirtualCell.random(IRB2600, TARGETS, seed=seed)
    q = cell.sample_poses(1, np.random.default_rng(seed))[0]  # in range, SMRs facing the tracker
    clock = VirtualClock()
    world = SimulatedWorld(cell, clock, q_home=q)
    if settled:
        clock.sleep(60.0)
    dev = SimulatedTracker(world, clock, seed=seed, **tracker_kw)
    return SimpleNamespace(
        cell=cell, clock=clock, world=world, dev=dev, q=q, smr=world.smr_positions()
    )


@pytest.fixture
def rig():
    return make_rig()
