"""The physical cell behind the simulated devices: the true arm's motion over time and its SMRs.

The simulated controller moves the arm here; the simulated tracker looks here for SMRs. Both
read the same clock, so a virtual clock makes a campaign of hours run in seconds of wall time.
"""

from __future__ import annotations

import threading

import numpy as np

from robocal.solver.repeatability import RP_PER_SIGMA

from .cell import VirtualCell

# ABB IRB 2600-class axis speeds, deg/s; the slowest joint sets a move's duration.
DEFAULT_SPEEDS_DEG_S = (175.0, 175.0, 175.0, 360.0, 360.0, 360.0)
ACCEL_S = 0.6  # ramp up and down: a move lasts at least this long


class SimulatedWorld:
    """Where the true arm is at any time, and where its SMRs are."""

    def __init__(
        self,
        cell: VirtualCell,
        clock,
        q_home=None,
        speeds_deg_s=None,
        air_c: float = 20.0,
        air_drift_c_per_h: float = 0.3,
        repeatability_mm: float = 0.0,
        rng=None,
    ):
        self.cell, self.clock = cell, clock
        n = cell.true_robot.n_joints
        speeds = speeds_deg_s or (DEFAULT_SPEEDS_DEG_S + (360.0,) * n)[:n]
        self.speeds = np.deg2rad(np.asarray(speeds, dtype=float))
        q0 = np.zeros(n) if q_home is None else np.asarray(q_home, dtype=float)
        self._from = self._to = q0
        self._t0 = self._t1 = clock.now()
        self.air_c, self.air_drift = air_c, air_drift_c_per_h
        self._start = clock.now()
        self._lock = threading.RLock()  # command_move asks move_duration, which reads joints
        # the arm's repeatability: each move ends off its pose by an isotropic Gaussian of this
        # per-axis sigma (the SMRs moved alike: a data sheet's RP is of a point on the flange)
        self.arrival_sigma_mm = repeatability_mm / RP_PER_SIGMA
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self._arrival = np.zeros(3)

    def move_duration(self, q_target) -> float:
        """Seconds a joint move from the current position to q_target takes."""
        dq = np.abs(np.asarray(q_target, dtype=float) - self.joints())
        return float(max(ACCEL_S, np.max(dq / self.speeds) + ACCEL_S))

    def command_move(self, q_target) -> float:
        """Start a joint move (rad) now; returns its duration in seconds."""
        with self._lock:
            q_now = self._joints_locked()
            duration = self.move_duration(q_target)
            self._from, self._to = q_now, np.asarray(q_target, dtype=float)
            self._t0 = self.clock.now()
            self._t1 = self._t0 + duration
            if self.arrival_sigma_mm > 0:
                self._arrival = self._rng.normal(scale=self.arrival_sigma_mm, size=3)
        return duration

    def stop(self) -> None:
        """Halt where the arm is."""
        with self._lock:
            q = self._joints_locked()
            self._from = self._to = q
            self._t0 = self._t1 = self.clock.now()

    def _joints_locked(self):
        t = self.clock.now()
        if t >= self._t1 or self._t1 == self._t0:
            return self._to.copy()
        s = (t - self._t0) / (self._t1 - self._t0)
        s = s * s * (3.0 - 2.0 * s)  # smooth start and stop
        return self._from + s * (self._to - self._from)

    def joints(self) -> np.ndarray:
        """True joint angles (rad) now."""
        with self._lock:
            return self._joints_locked()

    def moving(self) -> bool:
        with self._lock:
            return self.clock.now() < self._t1

    def since_arrival(self) -> float:
        """Seconds since the last move ended (negative while moving)."""
        with self._lock:
            return self.clock.now() - self._t1

    def elapsed(self) -> float:
        """Seconds since the world started (the campaign's time axis)."""
        return self.clock.now() - self._start

    def air_temperature(self) -> float:
        """Air temperature now (degC): a slow drift, plus any warming the cell's effects ask for."""
        hours = self.elapsed() / 3600.0
        rise = sum(getattr(e, "temperature_rise_c", 0.0) for e in self.cell.effects)
        return self.air_c + self.air_drift * hours + rise * (1.0 - np.exp(-hours / 0.5))

    def smr_positions(self) -> np.ndarray:
        """True SMR centres (K, 3) in the tracker frame now, with the cell's effects applied."""
        q = self.joints()[None]
        t = np.array([self.elapsed()])
        return self.cell.true_points(q, t, np.array([self.air_temperature()]))[0] + self._arrival
