"""What the campaign engine asks of its devices, its predictor and its sink.

The engine runs on the real clients (drivers/abb, drivers/tracker), on the simulated devices and
on the fakes the tests inject faults through; these protocols are the whole of what it may call,
so a static reader sees every device call typed and a fake that lacks one fails the type check.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from .abb.client import MoveTicket


class Reading(Protocol):
    """A tracker's stationary measurement: the SMR's mean centre (mm) and whether it is OK."""

    mean_mm: np.ndarray
    status: str | None


class Arm(Protocol):
    """The robot controller: absolute joint moves (deg), a stop latch, the joints it reports."""

    last_move: MoveTicket | None  # the last move started (None: none yet, or not told)

    @property
    def stopped(self) -> bool: ...

    def move_abs_j(self, q_deg) -> float | None: ...

    def wait_in_position(self, clock) -> None: ...

    def joints(self): ...

    def emergency_stop(self) -> bool: ...

    def clear_stop(self) -> None: ...


class Beam(Protocol):
    """The laser tracker: point the beam, search around it, measure, read the weather. A tracker
    with a stable-probing mode also has measure_stable(samples, wait_s) (TrackerClient: STABLE);
    the engine looks for it, so fakes without it keep settling on looks."""

    def point(self, xyz) -> bool: ...

    def search(self, radius_mm: float) -> bool: ...

    def measure(self, samples: int) -> Reading: ...

    def weather(self): ...


class Predictor(Protocol):
    """Where each SMR is expected at given joints (rad), refined as readings arrive."""

    @property
    def names(self) -> Sequence[str]: ...

    @property
    def stage(self) -> str: ...  # nominal, given, rigid, calibrated

    def reach_mm(self, q_rad) -> float: ...  # how far off the SMRs may be at joints q_rad

    def predict(self, q_rad) -> np.ndarray: ...

    def correct(self, predicted, measured) -> np.ndarray: ...

    def update(self, q_rad, meas) -> object: ...


class Sink(Protocol):
    """Where each reading and each pose's outcome goes the moment it is known (the store)."""

    def reading(self, *, pose_index: int, target: str, measurement, time_s: float, weather): ...

    def pose_done(self, *, pose_index: int, state: str, q_deg) -> None: ...
