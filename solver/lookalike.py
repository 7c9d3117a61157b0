"""A small campaign's joint scale or periodic term held to the joint range it was fitted on when
its look-alikes part beyond it (issue 21, point 3).

Over part of a joint's range a scale, a first or second harmonic and the gravity torque of that
joint look alike: fitted on 30 poses, each explains the covered range as well as the others (a
paired t over the held-out poses below the alternatives' bar), yet past it they part. The data
cannot choose there, so the deployed effect keeps its value at the edge of the covered range
(Extension.held) instead of extrapolating the one the campaign happened to pick. Several
look-alikes each just past the bar are judged together (`untold`): the chance that one of them
fits as well is held to one comparison's bar. A look-alike that parts by less than the final
model's held-out RMS leaves the effect whole. Looked for as far past the covered range as the
range is wide, within the joint limits.

Measured on simulated 30-pose one-SMR campaigns fitted on one half of joint 2's or 3's range
with a hidden periodic error (24 seeds): the half-range ones that named a scale or the other
harmonic tested 1.10-2.82x geometry on the other half (5 of 48); held, at most 1.10x, and with
look-alikes judged together at most 1.00x (the 1.10x one 0.98x).
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


@dataclass(frozen=True)
class Parting:
    """A look-alike that parts from the effect past its covered range."""

    label: str
    t: float  # paired t over the held-out poses of its squared errors less the effect's
    mm: float  # RMS difference of their predictions past the range


def untold(parts: list[Parting], poses: int) -> list[Parting]:
    """The look-alikes the data cannot tell from the effect, in the candidates' order: each one
    below the bar on its own, and the closest others until their chances of fitting as well add
    up to it; none when all of their chances together stay below it.

    A look-alike below the alternatives' bar (paired t under T_SIMPLER) is one the data cannot
    tell apart. With several look-alikes the effect is the best of them all, and each comparison
    may clear the bar while the chance that one of them fits as well does not: that chance is at
    most the sum of each one's (its one-sided p under Student's t over the poses), held to the
    same bar as one comparison's (the p of T_SIMPLER). With one look-alike it is the single bar.
    Measured on simulated 30-pose one-SMR campaigns fitted on half a joint's range (sim_small,
    24 seeds, 72 half-range fits): a joint-2 second harmonic named for a first (t 2.28, 2.45
    and 2.56 against its three look-alikes; 1.10x geometry on the other half) and a joint-3 scale
    for a first harmonic (t 2.04, 3.09, 2.31; 0.73x) are held (0.98x, 0.33x); the true harmonics
    with one close look-alike (sums 0.009-0.012, bar 0.028) stay whole (0.12-0.14x; held 0.5-0.6x).
    A stricter single bar (t 3) would hold those two as well; t 2.5 would hold a true harmonic
    fitted on 30 random poses (0.22x -> 0.26x). The real campaigns' small splits (IRB 120, QKM,
    the UR5's 30-40-pose subsets) hold what the single bar held.
    """
    from scipy.stats import t as student

    bar = float(student.sf(T_SIMPLER, poses - 1))
    chance = [(float(student.sf(p.t, poses - 1)), p) for p in parts]
    chance.sort(key=lambda cp: -cp[0])
    if sum(c for c, _ in chance) < bar:
        return []
    taken, total = [], 0.0
    for c, p in chance:  # each one below the bar on its own, then the closest to reach it
        if total >= bar and c < bar:
            break
        taken.append(p)
        total += c
    return [p for p in parts if any(p is t for t in taken)]  # in the candidates' order


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
        parts = list[Parting]()
        for c in lookalikes(cands, e):
            cv = _from_geometry(diag, [c if o is e else o for o in exts])
            xa, ea = cv.fits["all"]
            d = _rms(predict_extended(layout, xa, ea, moved) - here)
            if d > final.rmse:  # one that stays within the held-out RMS past the range is moot
                parts.append(Parting(c.label(), paired_t(cv.sq, final.sq), d))
        told = untold(parts, len(final.sq))
        names = [p.label for p in told]
        parting = max((p.mm for p in told), default=0.0)
        if names:
            out[i] = Extension(**{**e.__dict__, "held": np.array([lo, hi])})
            rng = (float(np.degrees(lo)), float(np.degrees(hi)))
            held.append(Held(e.label(), j + 1, rng, tuple(names), parting, final.rmse))
    return out, held
