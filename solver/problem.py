"""The calibration problem: the arm, its SMRs and the readings, checked once for every entry point."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .finite import require_inputs
from .robot import Robot

if TYPE_CHECKING:
    from .effects import Inputs
    from .measurements import Measurements


def _array(a, what: str, ndim: int) -> np.ndarray:
    """a as a float array of ndim dimensions, or a clear ValueError naming what it is."""
    out = np.asarray(a, dtype=float)
    if out.ndim != ndim:
        raise ValueError(f"{what} must have {ndim} dimensions, not {out.ndim}")
    return out


def _optional(a, what: str, shape: tuple) -> np.ndarray | None:
    """a as a float array of the given shape, or None."""
    if a is None:
        return None
    out = np.asarray(a, dtype=float)
    if out.shape != shape:
        raise ValueError(f"{what} has shape {out.shape}, the readings need {shape}")
    return out


# eq=False: arrays compare element-wise, so the problem keeps identity equality and a hash.
@dataclass(frozen=True, eq=False)
class Problem:
    """One campaign to fit: the arm, its SMRs' nominal positions and the readings, radians inside."""

    robot: Robot
    targets: np.ndarray  # (K, 3) mm, nominal SMR centres in the flange frame
    target_names: tuple[str, ...]
    q: np.ndarray  # (m, n) rad
    meas: np.ndarray  # (m, K, 3) mm in the tracker frame, NaN where missing
    base_guess: np.ndarray | None = None  # 4x4 base in the tracker frame (mm); None: registered
    time_s: np.ndarray | None = None  # (m, K) s, NaN where missing
    temp_c: np.ndarray | None = None  # (m, K) degC, NaN where missing
    prev_q: np.ndarray | None = None  # (m, n) rad the joints before each pose, NaN rows: not given
    pose_ids: tuple[str, ...] | None = None  # (m,) the campaign's names of the poses
    # the cell's tracker block (mpe_um, mpe_um_per_m) when it gave one; None: the default spec
    tracker_spec: dict | None = None
    # the tracker's noise (3-D RMS a reading) calibrate() judges identifiability against;
    # None: the default spec's
    noise_floor_mm: float | None = None

    def __post_init__(self):
        q = _array(self.q, "the joint angles", 2)
        meas = _array(self.meas, "the measured SMR positions", 3)
        targets = _array(self.targets, "the nominal SMR positions", 2)
        names = tuple(self.target_names)
        m, n = q.shape
        if meas.shape[0] != m or meas.shape[2:] != (3,):
            raise ValueError(f"the readings have shape {meas.shape}, {m} poses need ({m}, K, 3)")
        if targets.shape != (len(names), 3) or meas.shape[1] != len(names):
            raise ValueError(
                f"{len(names)} target names, {targets.shape[0]} nominal positions and "
                f"{meas.shape[1]} readings a pose do not agree"
            )
        base = None if self.base_guess is None else _array(self.base_guess, "the base guess", 2)
        require_inputs(q, meas, targets, base)
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen: once, here)
        set_("q", q)
        set_("meas", meas)
        set_("targets", targets)
        set_("target_names", names)
        set_("base_guess", base)
        set_("time_s", _optional(self.time_s, "time_s", (m, len(names))))
        set_("temp_c", _optional(self.temp_c, "temp_c", (m, len(names))))
        set_("prev_q", _optional(self.prev_q, "prev_q", (m, n)))
        if self.pose_ids is not None:
            ids = tuple(self.pose_ids)
            if len(ids) != m:
                raise ValueError(f"{len(ids)} pose ids for {m} poses")
            set_("pose_ids", ids)

    @classmethod
    def of(cls, robot: Robot, targets, meas: Measurements, base_guess=None, **extra) -> Problem:
        """The problem of a campaign's Measurements (targets in its target_names' order)."""
        return cls(
            robot,
            targets,
            meas.target_names,
            meas.q,
            meas.xyz,
            base_guess,
            time_s=meas.time_s,
            temp_c=meas.temp_c,
            prev_q=meas.prev_q,
            pose_ids=tuple(meas.pose_ids),
            **extra,
        )

    @property
    def mask(self) -> np.ndarray:
        """(m, K) True where a reading was taken."""
        return np.all(np.isfinite(self.meas), axis=-1)

    @property
    def n_poses(self) -> int:
        return self.q.shape[0]

    def inputs(self) -> Inputs:
        """The per-pose inputs the model's extensions read (joints, time, temperature, motion)."""
        from .effects import Inputs

        seen = self.mask.any(axis=1)

        def filled(a):
            # a pose with no reading (its beams all broken) has no time or temperature either;
            # every fit masks its rows out, so any finite value serves, and the campaign's
            # thermal drift stays a candidate (it needs a value at every pose)
            if a is None or seen.all() or not np.isfinite(a).any():
                return a
            return np.where(~seen[:, None] & ~np.isfinite(a), np.nanmean(a), a)

        return Inputs(self.q, filled(self.time_s), filled(self.temp_c), prev_q=self.prev_q)

    def subset(self, rows) -> Problem:
        """The problem restricted to the poses at rows (indices or a boolean mask), for folds."""
        rows = np.asarray(rows)
        if rows.dtype == bool:
            rows = np.flatnonzero(rows)
        pick = lambda a: None if a is None else a[rows]  # noqa: E731
        return replace(
            self,
            q=self.q[rows],
            meas=self.meas[rows],
            time_s=pick(self.time_s),
            temp_c=pick(self.temp_c),
            prev_q=pick(self.prev_q),
            pose_ids=None if self.pose_ids is None else tuple(self.pose_ids[i] for i in rows),
        )

    def with_meas(self, meas) -> Problem:
        """The same problem with other readings (m, K, 3) mm: screened, perturbed, simulated."""
        return replace(self, meas=meas)
