"""The nested blocks of a diagnosis report (FORMATS.md section 5), typed: each writes its JSON
with the keys in the order report.json has them."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any


def _with_joint(out: dict[str, Any], joint: int | None, harmonic: int | None = None) -> None:
    # joint and harmonic are written only for the effects that have them, after name and label
    if joint is not None:
        out["joint"] = joint
    if harmonic is not None:
        out["harmonic"] = harmonic


@dataclass(frozen=True)
class Significance:
    """Why an effect was accepted: its z against the campaign's own null."""

    z: float
    threshold: float
    p_value: float


@dataclass(frozen=True)
class Alternative:
    """A candidate the data could not tell apart from an accepted effect."""

    name: str
    label: str  # joint_periodic(3, harmonic 2)
    joint: int | None  # joints from 1; None for an effect of no joint
    harmonic: int | None
    holdout_rmse_mm: float

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "label": self.label}
        _with_joint(out, self.joint, self.harmonic)
        out["holdout_rmse_mm"] = self.holdout_rmse_mm
        return out


@dataclass(frozen=True)
class FoldResult:
    """The final model and geometry on test poses off the training region."""

    test: str  # the test poses' side of the split, e.g. `q2 >= 12.3 deg`
    test_poses: int
    beyond_training_deg: float
    geometric_rmse_mm: float | None  # None where no finite figure
    final_rmse_mm: float | None
    worse_only_in_geometric_span: bool


@dataclass(frozen=True)
class Refused:
    """An effect the random folds accepted that did not hold off the training region."""

    name: str
    label: str
    joint: int | None
    worse_on: list[str]  # the folds it made worse than geometry, in a phrase each
    # why refused, in a sentence: the folds, a term no gear can have, a reversed stiffness
    reason: str

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "label": self.label}
        _with_joint(out, self.joint)
        out["worse_on"] = self.worse_on
        out["reason"] = self.reason
        return out


@dataclass(frozen=True)
class ExtrapolationReport:
    """The report's `extrapolation` block: the final model tested off its training region."""

    method: str
    max_ratio_to_geometric: float
    folds: list[FoldResult]
    refused: list[Refused]
    joint_range_deg: list[list[float]]  # per joint, the [min, max] the data covers

    def to_json(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "max_ratio_to_geometric": self.max_ratio_to_geometric,
            "folds": [asdict(f) for f in self.folds],
            "refused": [r.to_json() for r in self.refused],
            "joint_range_deg": self.joint_range_deg,
        }


@dataclass(frozen=True)
class ResampledEffect:
    """An effect named on resamples of a small campaign."""

    effect: str  # joint_compliance(2)
    named_in: int  # resamples that named it
    in_final: bool  # whether the final model has it


@dataclass(frozen=True)
class StabilityReport:
    """The report's `stability` block: the effects named on resamples of a small campaign."""

    resamples: int
    poses_each: int
    named_nothing: int
    agreeing: int
    effects: list[ResampledEffect]
    doubt: str | None  # why the answer is in doubt, in a sentence; None when it is not
    # the whole campaign's causes, replaced by the one the resamples agree on (None: kept)
    replaced: list[str] | None = None
    agreed: str | None = None  # that replacement, in a sentence
    half_way: str | None = None  # why the model is half way to geometry (solver.hedge), if it is
    # per effect held to the joint range it was fitted on (solver.lookalike), why
    held: list[str] | None = None

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class CrossValidation:
    """What the diagnosis's cross-validation cost: folds, fits and candidates tried."""

    folds: int
    fits: int
    candidates: int
