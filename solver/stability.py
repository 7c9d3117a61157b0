"""Whether a small campaign names the same causes on resamples of itself (issue 21, point 3).

On 30-40 poses a few poses can decide which of two look-alike effects wins (a joint's compliance
or its second harmonic). The diagnosis's top effect is sought again on RESAMPLES subsets of the
campaign, each leaving out every RESAMPLES-th pose from another start. The answer stands when a
majority of them name a cause the final model has (more than MAJORITY of the resamples): one
naming nothing or another cause counts against it, for a cause that 29 of 36 poses do not find
is one a few poses decide (the real IRB 120's 30-pose folds named joint-2 compliance on 1 of 5).
It is in doubt too when an effect the final model lacks is named on more than RESAMPLES - AGREE
resamples (a rival). The report says the doubt. A campaign that names nothing is not
resampled: no effect is already the cautious answer.

When a cause the final model lacks is named on a majority of the resamples, and each cause of the
final model on one at most, the resamples agree on it and not on the whole campaign's choice
(which a few poses decided): the selection on all the poses is offered that cause alone
(`agreed_cause`: its null, cross-validation and region folds, as always). Accepted, the final
model takes it; refused, neither answer stands and the model is the geometric one, the effects
said suspected, not in it. Measured: on the bench's 30-40-pose campaigns a
compliance-and-periodic case named joint 2's scale where the resamples named its compliance 4 of
5 (now the compliance: one more detection, 0.74 -> 0.69 of geometry on other poses); the real
IRB 120 fitted on its 18 poses with q5 at or below the median named joint 3's compliance and a
joint-2 harmonic (1.26x geometry on the other 18), the resamples joint 2's compliance, which a
region fold refuses on all 18: geometry (1.00x). A real QKM half whose resamples named joint 3's
compliance on 3 and the final joint 2's on 2 is left alone (0.23 of geometry with joint 2's, 0.51
with joint 3's). Doubt alone decides nothing: on the real UR5's random 30-40-pose subsets the
effects named in doubt test 0.93-1.03x geometry (mean 0.97), and on the real IRB 120 and QKM
halves 0.23-0.69x, so deploying geometry in doubt loses more than it saves; the two worst UR5
subsets (1.08x, 1.02x) were not in doubt. What tells them apart is the size of the gain
(solver.hedge: a weak one is deployed half way).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .report_blocks import ResampledEffect, StabilityReport

RESAMPLE_MAX_POSES = 40  # larger campaigns are not resampled (their answer does not hinge on a few)
RESAMPLES = 5
AGREE = 4
# the share of resamples that must name a cause of the final model: a strict majority (3 of 5)
MAJORITY = 0.5


def effect_key(e) -> tuple:
    """An effect's identity across variants: kind, joint (0-based) and harmonic."""
    return (e.name, e.joint, e.harmonic)


def key_label(key: tuple) -> str:
    """joint_compliance(2), joint_periodic(3, harmonic 2), thermal_drift."""
    name, joint, harmonic = key
    where = [] if joint is None else [str(joint + 1)]
    where += [] if harmonic is None else [f"harmonic {harmonic}"]
    return name + (f"({', '.join(where)})" if where else "")


def leave_out(m: int, k: int = RESAMPLES) -> list[np.ndarray]:
    """The k resamples of m poses: each leaves out every k-th pose from its own start."""
    return [np.setdiff1d(np.arange(m), np.arange(r, m, k)) for r in range(k)]


@dataclass(frozen=True)
class Stability:
    """The effects the resamples named, against the final model's."""

    poses_each: int
    final: tuple  # effect keys of the final model
    named: tuple  # per resample, the effect keys it named
    replaced: tuple = ()  # the whole campaign's causes, when the resamples agreed on another
    agreed_on: tuple | None = None  # that cause (in the final model unless all poses refuse it)
    half_way: float | None = None  # a weak effect's held-out gain, when deployed half way (hedge)
    held: tuple = ()  # solver.lookalike.Held: effects held to the joint range they were fitted on

    def count(self, key: tuple) -> int:
        return sum(key in keys for keys in self.named)

    def keys(self) -> list[tuple]:
        """The final model's effects, then every other effect a resample named, most often first."""
        others = {k for keys in self.named for k in keys} - set(self.final)
        return list(self.final) + sorted(others, key=lambda k: (-self.count(k), key_label(k)))

    def agreeing(self) -> int:
        """Resamples that named a cause the final model has."""
        return sum(any(k in self.final for k in keys) for keys in self.named)

    def rival(self) -> tuple | None:
        """The cause the resamples agree on in the final model's place: one it lacks, named on
        a majority of them, while each cause it has is named on at most RESAMPLES - AGREE (one);
        None otherwise."""
        n = len(self.named)
        others = [k for k in self.keys() if k not in self.final]
        if not others:
            return None
        top = others[0]  # keys() puts the most often named first
        # the final model's causes are not reproduced: each on no more resamples than a rival
        # may be named on without doubt (a real QKM half, joint-2 compliance on 2 of 5 and
        # joint 3's on 3, tests at 0.23 of geometry with joint 2's, 0.51 with joint 3's)
        alone = max((self.count(k) for k in self.final), default=0) <= n - AGREE
        return top if self.count(top) > MAJORITY * n and alone else None

    def agreed(self) -> str | None:
        """What the final model took from the resamples, in a sentence; None when nothing."""
        if not self.replaced or self.agreed_on is None:
            return None
        n = len(self.named)
        gave = ", ".join(f"{key_label(k)} (on {self.count(k)} of {n})" for k in self.replaced)
        said = (
            f"the resamples of the campaign ({self.poses_each} poses each) agree on another "
            f"cause than the whole campaign's first choice, {gave}: "
            f"{key_label(self.agreed_on)} (named on {self.count(self.agreed_on)} of {n})"
        )
        if self.final:
            return f"{said}; the model takes it instead"
        return (
            f"{said}, which does not hold on all the poses (extrapolation.refused); neither "
            "stands: the model is the geometric one, and these effects are suspected, not in "
            "it; measure more poses before acting on them"
        )

    def halved(self) -> str | None:
        """Why the model is half way between geometry and the extended fit; None if it is not."""
        if self.half_way is None:
            return None
        return (
            f"the effects remove {self.half_way:.0%} of geometry's held-out RMS on this small "
            "campaign, within what the fit's own noise gives: the model is half way between "
            "geometry and the extended fit (geometry's parameters and the extended fit's, each "
            "half; the effects at half their fitted size); measure more poses to fit them whole"
        )

    def doubt(self) -> str | None:
        """Why the resamples put the answer in doubt, in a sentence; None when they do not."""
        n = len(self.named)
        if self.replaced and not self.final:
            return None  # the geometric model deployed: the agreed sentence says why
        rivals = [k for k in self.keys() if k not in self.final and self.count(k) > n - AGREE]
        if not rivals and self.agreeing() > MAJORITY * n:
            return None
        said = [f"{key_label(k)} named on {self.count(k)} of {n}" for k in self.keys()]
        nothing = sum(not keys for keys in self.named)
        said += [f"nothing on {nothing} of {n}"] if nothing else []
        return (
            f"the cause is in doubt: on {n} resamples of the campaign ({self.poses_each} poses "
            f"each), {'; '.join(said)} (the final model's causes need more than half); measure "
            "more poses before acting on these effects"
        )

    def to_report(self) -> StabilityReport:
        """The report's `stability` block."""
        return StabilityReport(
            resamples=len(self.named),
            poses_each=self.poses_each,
            named_nothing=sum(not keys for keys in self.named),
            agreeing=self.agreeing(),
            effects=[
                ResampledEffect(key_label(k), self.count(k), k in self.final) for k in self.keys()
            ],
            doubt=self.doubt(),
            replaced=[key_label(k) for k in self.replaced] or None,
            agreed=self.agreed(),
            half_way=self.halved(),
            held=[h.sentence() for h in self.held] or None,
        )


def agreed_cause(diag, cands, stability: Stability, chosen: tuple, log=None, clock=None):
    """The selection on all the poses, offered only the cause the resamples agree on
    (Stability.rival) and its variants: `chosen`, the diagnosis's (steps, final CV, region
    verdict), replaced by its answer when it accepts that cause, and the stability with the
    final model's keys updated; unchanged when there is no such cause or the selection refuses it.
    """
    from .diagnose import select_holding  # diagnose imports this module

    rival = stability.rival()
    if rival is None:
        return chosen, stability
    if log:
        log(f"  the resamples agree on {key_label(rival)}: the selection offered it alone")
    pool = [c for c in cands if effect_key(c) == rival]
    steps, base, final, region = select_holding(diag, pool, log, 1, clock)
    refused = chosen[2].refused + region.refused  # each refusal said, from either selection
    # refused on all the poses, neither answer stands: the model is the geometric one
    out = (steps, final if steps else base, replace(region, refused=refused))
    keys = tuple(effect_key(st[0]) for st in steps)
    return out, replace(stability, final=keys, replaced=stability.final, agreed_on=rival)


def resampled(diag, cands, steps) -> Stability | None:
    """On a small campaign that names effects, the effects named on resamples of it; None
    otherwise (naming nothing is the cautious answer already)."""
    from . import identify
    from .diagnose import Diagnoser, select_suspecting  # diagnose imports this module

    m = diag.prob.q.shape[0]
    if m > RESAMPLE_MAX_POSES or not steps:
        return None
    named = []
    subsets = leave_out(m)
    for keep in subsets:
        prob = identify.Problem(diag.prob.layout, diag.prob.q[keep], diag.prob.meas[keep])
        inputs, d = diag.inputs.subset(keep), diag  # fits start where the campaign's did
        sub = Diagnoser(prob, d.x0, d.free, inputs, prior=d.prior, shrunk=d.shrunk, start=d.start)
        chosen, _, _, _ = select_suspecting(sub, cands, max_effects=1)  # the top cause may differ
        named.append(tuple(effect_key(st[0]) for st in chosen))
    final = tuple(effect_key(st[0]) for st in steps)
    return Stability(min(map(len, subsets)), final, tuple(named))
