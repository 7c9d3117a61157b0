"""The virtual cell's devices, assembled: a simulated tracker and controller serving real
127.0.0.1 sockets on one clock, with the hidden physics a campaign asks for."""

from __future__ import annotations

import numpy as np

from .abb.sim import SimulatedController, serve_controller
from .cell import TrackerSpec, VirtualCell
from .effects import make_effects
from .tracker.sim import SimulatedTracker, serve_tracker
from .world import SimulatedWorld

ARRIVAL_STREAM = 31  # the arm's arrival scatter draws from a stream of its own per seed


class SimulatedCell:
    """The virtual cell's devices: a simulated tracker and controller on 127.0.0.1 sockets."""

    def __init__(
        self,
        robot,
        targets: dict,
        tracker: dict,
        seed: int,
        clock,
        beam_break_rate: float = 0.0,
        effects=(),
        expected_s: float = 2000.0,
        noise_seed=None,
        repeatability_mm: float | None = None,
        base=None,
    ):
        # the cell's base, where it gives one, places the arm (a wall or ceiling mount): a
        # tracker placed at random instead saw none of the SMRs the plan aimed it at
        self.cell = VirtualCell.random(
            robot, targets, seed=seed, tracker=TrackerSpec.of(tracker), base=base
        )
        self.cell.effects.extend(make_effects(list(effects), self.cell, seed))
        noise = seed if noise_seed is None else noise_seed
        self.world = SimulatedWorld(
            self.cell,
            clock,
            repeatability_mm=repeatability_mm or 0.0,
            rng=np.random.default_rng([*np.atleast_1d(noise).tolist(), ARRIVAL_STREAM]),
        )
        # effects tied to the campaign's time axis (a base shift's moment, thermal T0) learn it
        # from the expected duration, as VirtualCell.campaign tells them the real one
        span = np.linspace(0.0, expected_s, 50)[:, None]
        for e in self.cell.effects:
            if hasattr(e, "start_campaign"):
                e.start_campaign(self.cell, span, np.full_like(span, self.world.air_temperature()))
        self.tracker_device = SimulatedTracker(
            self.world,
            clock,
            beam_break_rate=beam_break_rate,
            seed=noise,
        )
        self.controller_device = SimulatedController(self.world, robot, clock)
        self.tracker_server = serve_tracker(self.tracker_device)
        self.controller_server = serve_controller(self.controller_device)

    def rough_base(self, seed: int) -> np.ndarray:
        """What a quick survey of the cell gives (see `surveyed_base`)."""
        return surveyed_base(self.cell.base, seed)

    def close(self):
        self.tracker_server.close()
        self.controller_server.close()


def surveyed_base(true_base: np.ndarray, seed: int) -> np.ndarray:
    """The true base some 10 mm and half a degree off, as a quick survey of the cell gives it."""
    rng = np.random.default_rng([seed, 7])
    base = true_base.copy()
    base[:3, 3] += rng.normal(0.0, 6.0, 3)
    a = np.deg2rad(rng.normal(0.0, 0.3))
    c, s = np.cos(a), np.sin(a)
    base[:3, :3] = base[:3, :3] @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return base
