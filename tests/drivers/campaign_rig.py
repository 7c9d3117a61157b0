"""A campaign engine on the simulated cell: real clients on 127.0.0.1 sockets, a virtual clock."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from robocal.drivers.abb.client import ControllerClient
from robocal.drivers.campaign import CampaignEngine, Settings
from robocal.drivers.clock import VirtualClock
from robocal.drivers.planning import order_poses
from robocal.drivers.predictor import SmrPredictor
from robocal.drivers.simulated_cell import SimulatedCell
from robocal.drivers.tracker.client import TrackerClient
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS


class Readings:
    """A sink keeping each reading with the time it was handed over."""

    def __init__(self):
        self.readings, self.poses = {}, []

    def reading(self, *, pose_index, target, measurement, time_s, weather):
        self.readings[(pose_index, target)] = (np.asarray(measurement.mean_mm), time_s)

    def pose_done(self, *, pose_index, state, q_deg):
        self.poses.append((pose_index, state))


@contextmanager
def simulated_engine(seed: int = 3, n: int = 10, settings: Settings | None = None, predictor=None):
    """(engine, poses deg in a short order, simulated cell); the devices close on exit."""
    clock = VirtualClock()
    sim = SimulatedCell(IRB2600, TARGETS, {}, seed, clock)
    tracker = TrackerClient("127.0.0.1", sim.tracker_server.port)
    controller = ControllerClient(sim.controller_server.url, IRB2600)
    try:
        names = tuple(TARGETS)
        q = sim.cell.sample_poses(n, np.random.default_rng(seed))
        q = q[order_poses(q, np.zeros(IRB2600.n_joints))]
        pred = predictor or SmrPredictor(
            IRB2600, np.array([TARGETS[t] for t in names]), names, sim.rough_base(seed)
        )
        engine = CampaignEngine(
            controller, tracker, clock, pred, Readings(), settings or Settings(settle="adaptive")
        )
        yield engine, np.rad2deg(q), sim
    finally:
        tracker.close()
        controller.close()
        sim.close()
