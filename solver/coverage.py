"""Which joints a campaign turns: one left at a single angle ties the geometry to that angle.

A joint the campaign never turns leaves the links on either side of it measured in one relative
position only: the data cannot separate their parameters (the calibration holds them or shrinks
them to nominal, correctly), and every held-out pose shares that angle, so the held-out error
says nothing of poses at any other. The last joint is left out: turning it only carries the SMRs
about its own axis, which the identified SMR positions describe at any of its angles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A joint turned through less than this over the campaign has not been exercised (a campaign
# over a narrow task region turns its joints through tens of degrees: the real UR5's q1 < 10 deg
# half spans 34 deg).
MIN_SPAN_DEG = 5.0


@dataclass(frozen=True)
class IdleJoint:
    """A joint the campaign hardly turns and the angles it was measured at (deg)."""

    joint: int  # from 1
    lo_deg: float
    hi_deg: float


def idle_joints(q: np.ndarray) -> list[IdleJoint]:
    """The joints but the last that the poses q (m, N) rad turn through less than MIN_SPAN_DEG."""
    deg = np.degrees(np.atleast_2d(np.asarray(q, dtype=float)))
    if deg.shape[0] == 0:
        return []
    lo, hi = deg.min(axis=0), deg.max(axis=0)
    return [
        IdleJoint(j + 1, float(lo[j]), float(hi[j]))
        for j in range(deg.shape[1] - 1)
        if hi[j] - lo[j] < MIN_SPAN_DEG
    ]


def idle_reason(idle: list[IdleJoint], poses: int) -> str | None:
    """The verdict's sentence on joints the campaign did not turn; None if it turned them all."""
    if not idle:
        return None
    named = ", ".join(f"joint {i.joint} ({i.lo_deg:.1f} to {i.hi_deg:.1f} deg)" for i in idle)
    return (
        f"the {poses} poses leave {named} at one angle (less than {MIN_SPAN_DEG:g} deg of "
        "motion): the held-out error holds at that angle only, and poses elsewhere get the "
        "nominal geometry the data could not correct; measure poses across its range"
    )
