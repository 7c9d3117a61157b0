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


def campaign_plan(
    poses_deg,
    target_names: Sequence[str],
    start: int = 0,
    partial: Mapping[str, object] | None = None,
) -> Iterator[Message]:
    """The messages that measure poses_deg[start:]; targets in `partial` (already read at pose
    `start`, cut off mid-pose) are not aimed at or measured again."""
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
    return _messages(poses, names, start, done)


def growing_plan(
    next_batch: Callable[[], np.ndarray | None],
    target_names: Sequence[str],
    start: int = 0,
    partial: Mapping[str, object] | None = None,
) -> Iterator[Message]:
    """The messages that measure batches of poses numbered on from `start`: next_batch() gives
    the next poses (m, joints) deg, None to end. The engine asks for a message only once the one
    before is done, so each batch is asked for after the previous batch's last Save (an
    adaptive campaign chooses it from every reading so far); `partial` as for campaign_plan."""
    names = tuple(target_names)
    done = set(partial or ())
    i = start
    while (batch := next_batch()) is not None:
        poses = np.atleast_2d(np.asarray(batch, dtype=float))
        yield from _messages(poses, names, i, done, first=i)
        i, done = i + len(poses), set()


def _messages(poses, names, start, done, first: int = 0) -> Iterator[Message]:
    """Pose `first + j` is poses[j]; from pose `start` on."""
    for i in range(start, first + len(poses)):
        yield Checkpoint(i)
        yield Move(i, tuple(float(v) for v in poses[i - first]))
        yield Settle(i)
        for name in names:
            if i == start and name in done:
                continue
            yield Aim(i, name)
            yield Measure(i, name)
        yield Save(i)
