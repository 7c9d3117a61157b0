"""Fixtures: a virtual cell's world on a VirtualClock, the simulated controller, its TCP server."""

import pytest

from robocal.drivers.abb.sim import SimulatedController, serve_controller
from robocal.drivers.cell import VirtualCell
from robocal.drivers.clock import VirtualClock
from robocal.drivers.world import SimulatedWorld
from robocal.solver.robot import IRB2600

TARGETS = {"A": [60, 0, 35], "B": [-30, 52, 35], "C": [-30, -52, 35]}


@pytest.fixture
def clock():
    return VirtualClock()


@pytest.fixture
def world(clock):
    return SimulatedWorld(VirtualCell.random(IRB2600, TARGETS, seed=1), clock)


@pytest.fixture
def device(world, clock):
    return SimulatedController(world, IRB2600, clock)


@pytest.fixture
def server(device):
    handle = serve_controller(device)
    yield handle
    handle.close()
