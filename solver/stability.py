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
"""

from __future__ import annotations

from dataclasses import dataclass

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

    def count(self, key: tuple) -> int:
        return sum(key in keys for keys in self.named)

    def keys(self) -> list[tuple]:
        """The final model's effects, then every other effect a resample named, most often first."""
        others = {k for keys in self.named for k in keys} - set(self.final)
        return list(self.final) + sorted(others, key=lambda k: (-self.count(k), key_label(k)))

    def agreeing(self) -> int:
        """Resamples that named a cause the final model has."""
        return sum(any(k in self.final for k in keys) for keys in self.named)

    def doubt(self) -> str | None:
        """Why the resamples put the answer in doubt, in a sentence; None when they do not."""
        n = len(self.named)
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
        )
