"""`robocal acquire --target-accuracy-mm T`: an adaptive campaign on the engine, batch by batch.

The plan stored first is the D-optimal seed set; once its last pose is saved, the engine asks
the plan for its next message, and the plan (drivers/plan.growing_plan) asks this module for the
next batch: a fast fit of every reading stored so far, the accuracy it predicts over the working
volume, and either the stop (stored with its reason) or the next poses, appended to the stored
plan before the arm moves to them. Each step's prediction is kept in the campaign's settings
(`adaptive_steps`) and reported to the progress line and the run's events.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from robocal.server import store
from robocal.server.acquisition.adaptive_effects import from_steps
from robocal.server.acquisition.adaptive_plan import (
    AdaptiveOptions,
    AdaptivePlanner,
    AdaptiveSummary,
    Step,
    ordered,
    plan_candidates,
)
from robocal.server.formats.cell_json import Cell

# The candidates' random stream, apart from the seed's other draws (a resumed run draws them
# again from the same seed, so the stored poses are found among them).
STREAM = 0xADA
DEFAULT_CANDIDATES = 400
STEPS = "adaptive_steps"  # the campaign settings' key of the steps so far


def adaptive_options(opts) -> AdaptiveOptions:
    """The adaptive campaign of acquire's options: the target, at most `poses` poses, chosen
    among `choose_from` candidates (default 400)."""
    return AdaptiveOptions(
        target_mm=float(opts.target_accuracy_mm),
        max_poses=int(opts.poses),
        candidates=max(int(opts.choose_from) or DEFAULT_CANDIDATES, int(opts.poses)),
    )


def _planner(cell: Cell, base, opts) -> AdaptivePlanner:
    a = adaptive_options(opts)
    rng = np.random.default_rng([opts.seed, STREAM])
    return AdaptivePlanner(cell, base, plan_candidates(cell, base, a.candidates, rng), a)


def base_guess_for(info) -> np.ndarray:
    """The base guess a stored campaign was planned from (4x4, mm)."""
    return np.array(info.settings["base_guess"], dtype=float)


def plan_seed(cell: Cell, base, opts) -> tuple[np.ndarray, dict]:
    """The seed set (deg) in a short tour from the home pose, and the plan's summary."""
    planner = _planner(cell, base, opts)
    idx = planner.seed()
    q = ordered(planner.candidates[idx], np.zeros(cell.robot.n_joints))
    return np.rad2deg(q), {
        "adaptive": {
            "target_accuracy_mm": planner.opts.target_mm,
            "max_poses": planner.opts.max_poses,
            "candidates": len(planner.candidates),
            "seed_poses": len(idx),
            "batch": planner.batch,
            "criterion": "seed: D-optimal; then I-optimal on the fit's identified parameters",
        }
    }


class AdaptiveRun:
    """The batches of a stored adaptive campaign `cid`, from its planned poses on.

    on_step(step, poses planned) hears each step's prediction after the store has it."""

    def __init__(self, db, cid: int, cell: Cell, base, opts, names, clock, on_step=None, steps=()):
        self.db, self.cid, self.names, self.clock = db, cid, tuple(names), clock
        self.on_step: Callable[[Step, int], None] = on_step or (lambda step, total: None)
        self.planner = _planner(cell, base, opts)
        self.planned = np.array(
            [p.joints_deg for p in store.planned_poses(db, campaign_id=cid)], dtype=float
        )
        cand = np.rad2deg(self.planner.candidates)
        # the stored poses among the candidates (a resumed run's draw is the same)
        near = np.abs(self.planned[:, None, :] - cand[None]).max(axis=-1) < 1e-6
        self.planner.taken = [int(np.argmax(row)) for row in near if row.any()]
        self.steps: list[Step] = [Step.from_json(s) for s in steps]  # as the settings keep them
        if self.steps:  # a resumed run fits the effects its last step included
            self.planner.effects = from_steps(self.steps[-1].extensions)
        self.last: Step | None = None

    def plan(self, start: int, partial=None, order=None):
        """The messages from pose `start` on: the stored poses left, then batch after batch;
        `order` as for plan.campaign_plan."""
        from robocal.drivers.plan import growing_plan

        left = [self.planned[start:]] if start < len(self.planned) else []

        def next_batch():
            if left:
                return left.pop()
            return self._next()

        return growing_plan(next_batch, self.names, start, partial, order)

    def _next(self):
        meas = store.campaign_measurements(self.db, campaign_id=self.cid, targets=self.names)
        step, chosen = self.planner.step(meas, self.clock.now())
        self.last = step
        if self.steps and self.steps[-1].poses == step.poses:
            self.steps.pop()  # a resumed run refits the poses its last step had: that step again
        self.steps.append(step)
        kept = [s.to_json() for s in self.steps]
        store.update_settings(self.db, campaign_id=self.cid, **{STEPS: kept})
        total = len(self.planned) + (0 if chosen is None else len(chosen))
        self.on_step(step, total)
        if chosen is None:
            return None
        start = np.deg2rad(self.planned[-1]) if len(self.planned) else None
        q = np.rad2deg(ordered(self.planner.candidates[chosen], start))
        store.extend_plan(self.db, campaign_id=self.cid, poses_deg=q)
        self.planned = np.vstack([self.planned, q])
        return q

    def summary(self) -> AdaptiveSummary:
        """The campaign's steps and, once it stopped, why."""
        last = self.last
        return AdaptiveSummary(
            target_accuracy_mm=self.planner.opts.target_mm,
            steps=tuple(self.steps),
            stopped=None if last is None or not last.stop else last.reason,
            message=None if last is None else last.message,
            predicted_mm=None if last is None else last.predicted_mm,
        )


def step_line(step: Step, target_mm: float) -> str:
    """The progress line's words for a step."""
    return (
        f"measuring: predicted {step.predicted_mm:.4f} mm at {step.poses} poses "
        f"(target {target_mm:.4f} mm)"
    )


def adaptive_run(db, cid, cell: Cell, base, opts, clock, known: dict, sink, on_event=None):
    """The adaptive campaign `cid`'s batches, each step told to the progress line (a sink with a
    progress bar, acquire's _Progress: its total and words), the pose events' sink (its total)
    and on_event; `known`: the campaign's stored settings (the steps so far)."""
    target = float(opts.target_accuracy_mm)

    def on_step(step: Step, total: int) -> None:
        s = sink
        while s is not None:  # the sinks acquire wrapped round one another
            if hasattr(s, "progress") and hasattr(s, "task"):
                s.progress.update(s.task, total=total, description=step_line(step, target))
            if hasattr(s, "total"):
                s.total = int(total)
            s = getattr(s, "sink", None)
        if on_event:
            on_event({"type": "campaign.adaptive", "campaign_id": cid, **step.to_json()})

    names = tuple(sorted(cell.targets))
    return AdaptiveRun(db, cid, cell, base, opts, names, clock, on_step, known.get(STEPS, ()))
