"""Simulated cells and measuring helpers for the solver's tests, without the server: the solver's
tests reach the solver and the simulator only (tests/solver/test_layering.py holds them to it)."""

from __future__ import annotations

import multiprocessing
import tracemalloc
from dataclasses import dataclass
from multiprocessing import forkserver

import numpy as np

from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600, Robot
from tests.robots import TARGETS


@dataclass
class SimCell:
    """A cell as the solver's tests need one: the arm, its SMRs (mm, flange frame), a base guess."""

    robot: Robot
    targets: dict[str, np.ndarray]
    base: np.ndarray | None = None  # 4x4 base-in-tracker guess, mm; None: registered

    def target_positions(self, names) -> np.ndarray:
        """(K, 3) the nominal positions of the named SMRs, in that order."""
        return np.array([self.targets[t] for t in names], dtype=float)

    def problem(self, meas, **extra) -> Problem:
        """The solver's problem of a campaign (Measurements) in this cell."""
        return Problem.of(
            self.robot, self.target_positions(meas.target_names), meas, self.base, **extra
        )


def default_cell() -> SimCell:
    """The spec's example cell (server default_cell's): the IRB 2600 with targets A, B, C."""
    return SimCell(IRB2600, {k: np.array(v) for k, v in TARGETS.items()})


def peak_mb(fn) -> float:
    """Peak memory (MiB) that fn() allocates, as tracemalloc sees it (numpy reports there)."""
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def smr_ring(k: int) -> np.ndarray:
    """k SMRs (k, 3) mm on a 60 mm ring of the flange, slightly out of plane (the scale bench's)."""
    w = np.linspace(0.0, 2 * np.pi, k, endpoint=False)
    return np.column_stack([60 * np.cos(w), 60 * np.sin(w), 35 + 5 * np.sin(3 * w)])


def in_child(fn, args: tuple, timeout: float):
    """fn(*args) run in a child process: its result, or TimeoutError (the child killed) past
    timeout s; for numerics that a regression could hang in native code."""
    ctx = multiprocessing.get_context("forkserver")
    # A fork server not yet started imports fn's module (numpy, the solver) too, once: each
    # child forks from it instead of importing them again (a second or more each). Added to
    # what it preloads already (the service's job modules: its API tests share the server).
    preload = getattr(forkserver._forkserver, "_preload_modules", None) or []
    ctx.set_forkserver_preload(
        [*preload, *(m for m in ("__main__", fn.__module__) if m not in preload)]
    )
    with ctx.Pool(1) as pool:
        return pool.apply_async(fn, args).get(timeout)
