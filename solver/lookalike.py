"""A small campaign's joint scale or periodic term held to the joint range it was fitted on when
its look-alikes part beyond it (issue 21, point 3).

Over part of a joint's range a scale, a first or second harmonic and the gravity torque of that
joint look alike: fitted on 30 poses, each explains the covered range as well as the others (a
paired t over the held-out poses below the alternatives' bar), yet past it they part. The data
cannot choose there, so the deployed effect keeps its value at the edge of the covered range
(Extension.held) instead of extrapolating the one the campaign happened to pick. A look-alike
that parts by less than the final model's held-out RMS leaves the effect whole. Looked for as
far past the covered range as the range is wide, within the joint limits.

Measured on simulated 30-pose one-SMR campaigns fitted on one half of joint 2's or 3's range
with a hidden periodic error (24 seeds): the half-range ones that named a scale or the other
harmonic tested 1.10-2.82x geometry on the other half (5 of 48); held, at most 1.10x.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .selection import paired_t
from .variants import T_SIMPLER
from .vocabulary import Extension, Inputs

HELD_KINDS = ("joint_scale", "joint_periodic")
REACH = 1.0  # how far past the covered range its look-alikes are compared, in covered widths
STEPS = (0.25, 0.5, 0.75, 1.0)  # where, in that reach


@dataclass(frozen=True)
class Held:
    """An effect held to the joint range it was fitted on, and the look-alikes that part past it."""

    effect: str  # its label
    joint: int  # 1-based
    range_deg: tuple[float, float]
    lookalikes: tuple[str, ...]  # labels of the look-alikes the data cannot tell from it
    parting_mm: float  # the largest RMS difference of their predictions past the range
    holdout_rmse_mm: float  # the final model's, the bar they parted by more than

    def sentence(self) -> str:
        lo, hi = self.range_deg
        return (
            f"{self.effect} and {', '.join(self.lookalikes)} fit the campaign alike but part "
            f"by {self.parting_mm:.3f} mm RMS past joint {self.joint}'s covered range "
            f"{lo:.0f}..{hi:.0f} deg (the held-out RMS is {self.holdout_rmse_mm:.3f} mm): "
            f"the data cannot choose there, so {self.effect} is held at its value at that "
            "range's edge beyond it; measure poses across the joint's range to fit it whole"
        )


def lookalikes(cands, e: Extension) -> list[Extension]:
    """The candidates on e's joint that look like it over part of its range: its scale, first
    and second harmonics and its one-stiffness compliance, e's own variant excepted."""
    return [
        c
        for c in cands
        if c.joint == e.joint
        and not (c.name == e.name and c.harmonic == e.harmonic)
        and (
            c.name in HELD_KINDS
            or (c.name == "joint_compliance" and c.masses is not None and c.keep is None)
        )
    ]


def beyond(inputs: Inputs, j: int, lo: float, hi: float, limits) -> Inputs | None:
    """The campaign's poses with joint j moved past [lo, hi], up to REACH widths, within its
    limits (each copy keeps its pose's time, temperature and motion); None when the range
    reaches both limits."""
    width = hi - lo
    ends = ((lo, max(lo - REACH * width, limits[0])), (hi, min(hi + REACH * width, limits[1])))
    angles = [
        edge + f * (far - edge) for edge, far in ends if abs(far - edge) > 1e-9 for f in STEPS
    ]
    if not angles:
        return None
    q = np.concatenate([inputs.q] * len(angles))
    q[:, j] = np.repeat(angles, len(inputs.q))
    n = len(angles)
    return Inputs(q, _tiled(inputs.time_s, n), _tiled(inputs.temp_c, n), _tiled(inputs.motion, n))


def _tiled(a: np.ndarray | None, n: int) -> np.ndarray | None:
    """n copies of a per-pose array one after the other (None stays None)."""
    return None if a is None else np.concatenate([a] * n)


def _from_geometry(diag, exts):
    """exts' cross-validation from the geometric start, the diagnoser's warm starts left as they
    were: they hold the final model's coefficients by position, where a look-alike of another
    kind (and size) takes its effect's place."""
    warm, diag.warm = diag.warm, {}
    try:
        return diag.cross_validate(exts)
    finally:
        diag.warm = warm


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(np.sum(d * d, axis=-1))))


def hold_lookalikes(diag, final, x, exts, cands) -> tuple[list, list[Held]]:
    """The final model's effects, each scale or periodic term held to its joint's covered range
    when a look-alike the data cannot tell from it parts past that range by more than the final
    held-out RMS; and what was held. `final` is the final model's CV (solver.diagnose.CV)."""
    from .extended import predict_extended  # extended imports the vocabulary this reads

    q, layout = diag.prob.q, diag.prob.layout
    robot = layout.robot
    out, held = list(exts), []
    for i, e in enumerate(exts):
        if e.name not in HELD_KINDS:
            continue
        j = e.joint
        lo, hi = float(q[:, j].min()), float(q[:, j].max())
        moved = beyond(diag.inputs, j, lo, hi, (robot.lower[j], robot.upper[j]))
        if moved is None:
            continue
        here = predict_extended(layout, x, exts, moved)
        parting, names = 0.0, list[str]()
        for c in lookalikes(cands, e):
            cv = _from_geometry(diag, [c if o is e else o for o in exts])
            if paired_t(cv.sq, final.sq) >= T_SIMPLER:
                continue  # the data tells it apart: worse on the held-out poses
            xa, ea = cv.fits["all"]
            d = _rms(predict_extended(layout, xa, ea, moved) - here)
            if d > final.rmse:
                parting, names = max(parting, d), names + [c.label()]
        if names:
            out[i] = Extension(**{**e.__dict__, "held": np.array([lo, hi])})
            rng = (float(np.degrees(lo)), float(np.degrees(hi)))
            held.append(Held(e.label(), j + 1, rng, tuple(names), parting, final.rmse))
    return out, held
