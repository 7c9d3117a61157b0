"""A measurement campaign as arrays: joint readings and SMR centres per pose."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Measurements:
    """Readings of K targets at m poses, in the tracker frame (mm) with joints in rad.

    Missing readings (beam breaks) are NaN in `xyz` and False in `mask`.
    """

    pose_ids: list[str]
    q: np.ndarray  # (m, n) rad
    target_names: tuple[str, ...]
    xyz: np.ndarray  # (m, K, 3) mm
    time_s: np.ndarray | None = None  # (m, K) s, NaN where missing
    temp_c: np.ndarray | None = None  # (m, K) degC, NaN where missing
    # (m, n) rad the joints the arm came from before each pose, NaN rows where not given
    prev_q: np.ndarray | None = None

    @property
    def mask(self) -> np.ndarray:
        return np.all(np.isfinite(self.xyz), axis=-1)

    @property
    def n_poses(self) -> int:
        return self.q.shape[0]

    @property
    def n_readings(self) -> int:
        return int(self.mask.sum())

    def subset(self, idx) -> Measurements:
        """The campaign restricted to the poses at `idx` (indices or a boolean mask)."""
        idx = np.asarray(idx)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)
        pick = lambda a: None if a is None else a[idx]  # noqa: E731
        return Measurements(
            [self.pose_ids[i] for i in idx],
            self.q[idx],
            self.target_names,
            self.xyz[idx],
            pick(self.time_s),
            pick(self.temp_c),
            pick(self.prev_q),
        )

    def select_targets(self, names) -> Measurements:
        """The campaign keeping only the named targets."""
        cols = [self.target_names.index(n) for n in names]
        pick = lambda a: None if a is None else a[:, cols]  # noqa: E731
        return Measurements(
            list(self.pose_ids),
            self.q,
            tuple(names),
            self.xyz[:, cols],
            pick(self.time_s),
            pick(self.temp_c),
            self.prev_q,
        )
