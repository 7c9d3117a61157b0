"""A campaign's plan: the small messages (move, settle, aim, measure, save, checkpoint) it is made of.

A plan says what to do and in which order; it touches no device, so a test can list it. The
engine (drivers/campaign.py) executes the messages and owns the campaign's state: it honours
pause and abort at each Checkpoint and before each Move (so neither lets a new move begin), and
an e-stop before every message.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Checkpoint:
    """Before pose `pose` is begun: the place where a pause or an abort takes effect."""

    pose: int


@dataclass(frozen=True)
class Move:
    """Command the arm to pose `pose` (joint angles in degrees) and wait until it is there."""

    pose: int
    q_deg: tuple[float, ...]
    # the SMR the pose's readings begin with (the beam is pointed at it ahead of arrival, and the
    # arm's ringing is judged on it); None: the first of the campaign's targets
    first: str | None = None


@dataclass(frozen=True)
class Settle:
    """Let the arm come to rest at pose `pose` (a fixed pause, or until readings agree)."""

    pose: int


@dataclass(frozen=True)
class Aim:
    """Point the tracker at the predicted position of `target` (searching if it does not lock)."""

    pose: int
    target: str


@dataclass(frozen=True)
class Measure:
    """Measure `target` (retrying after a beam break) and hand the reading to the sink at once."""

    pose: int
    target: str


@dataclass(frozen=True)
class Save:
    """Record pose `pose`'s outcome: measured, missing-target or skipped."""

    pose: int


Message = Checkpoint | Move | Settle | Aim | Measure | Save
Order = Callable[[np.ndarray], Sequence[str]]  # a pose's joints (deg) -> its targets, in order


def campaign_plan(
    poses_deg,
    target_names: Sequence[str],
    start: int = 0,
    partial: Mapping[str, object] | None = None,
    order: Order | None = None,
) -> Iterator[Message]:
    """The messages that measure poses_deg[start:]; targets in `partial` (already read at pose
    `start`, cut off mid-pose) are not aimed at or measured again. order(q_deg), if given, names
    the targets in the order to measure them at that pose (asked as the pose's Move is due)."""
    poses = np.asarray(poses_deg, dtype=float)
    if poses.ndim != 2:
        raise ValueError(f"poses_deg must be a (poses, joints) array, not shape {poses.shape}")
    if not 0 <= start <= len(poses):
        raise ValueError(f"start {start} is outside 0..{len(poses)}")
    names = tuple(target_names)
    done = set(partial or ())
    unknown = done - set(names)
    if unknown:
        raise ValueError(f"partial readings name unknown targets: {', '.join(sorted(unknown))}")
    return _messages(poses, names, start, done, order=order)


def growing_plan(
    next_batch: Callable[[], np.ndarray | None],
    target_names: Sequence[str],
    start: int = 0,
    partial: Mapping[str, object] | None = None,
    order: Order | None = None,
) -> Iterator[Message]:
    """The messages that measure batches of poses numbered on from `start`: next_batch() gives
    the next poses (m, joints) deg, None to end. The engine asks for a message only once the one
    before is done, so each batch is asked for after the previous batch's last Save (an
    adaptive campaign chooses it from every reading so far); `partial`, `order` as for
    campaign_plan."""
    names = tuple(target_names)
    done = set(partial or ())
    i = start
    while (batch := next_batch()) is not None:
        poses = np.atleast_2d(np.asarray(batch, dtype=float))
        yield from _messages(poses, names, i, done, first=i, order=order)
        i, done = i + len(poses), set()


def _messages(poses, names, start, done, first: int = 0, order=None) -> Iterator[Message]:
    """Pose `first + j` is poses[j]; from pose `start` on."""
    for i in range(start, first + len(poses)):
        yield Checkpoint(i)
        q = poses[i - first]
        ranked = names if order is None else _ranked(order(q), names)
        todo = [n for n in ranked if not (i == start and n in done)]
        lead = todo[0] if order is not None and todo else None
        yield Move(i, tuple(float(v) for v in q), lead)
        yield Settle(i)
        for name in todo:
            yield Aim(i, name)
            yield Measure(i, name)
        yield Save(i)


def _ranked(ranked: Sequence[str], names: tuple[str, ...]) -> tuple[str, ...]:
    """The order's targets, checked to be the campaign's, each once."""
    ranked = tuple(ranked)
    if sorted(ranked) != sorted(names):
        raise ValueError(f"a pose's target order {ranked} is not an order of {names}")
    return ranked
