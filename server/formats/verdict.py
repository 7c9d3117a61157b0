"""A model's verdict as every reader takes it: model.json's `validation` block, typed once."""

from __future__ import annotations

from dataclasses import dataclass

NO_VERDICT = "the model has no validation verdict (written before the guard); calibrate again"


@dataclass(frozen=True)
class Verdict:
    """Whether a model may be deployed, why not (one sentence a reason), and the accuracy to
    expect on poses it was not fitted on (mm); a model without a verdict is never deployable."""

    deployable: bool
    reasons: tuple[str, ...]
    holdout_rms_mm: float | None = None
    holdout_max_mm: float | None = None
    fit_rms_mm: float | None = None
    nominal_rms_mm: float | None = None  # the nominal arm's error on the same readings
    tolerance_mm: float | None = None
    noise_floor_mm: float | None = None
    noise_floor_source: str | None = None
    condition_number: float | None = None
    holdout: str | None = None  # how the held-out figures were had
    summary: str | None = None  # the expected accuracy in one sentence, without the reasons
    warnings: tuple[str, ...] = ()  # what deserves a look without making it undeployable

    @classmethod
    def of(cls, block: dict | None) -> Verdict:
        """The verdict of a `validation` block (as model.json and report.json hold it); without
        one, or without its `deployable`, the model is not deployable."""
        if not block or not isinstance(block.get("deployable"), bool):
            return cls(False, (NO_VERDICT,))
        reasons = tuple(block.get("reasons") or ())
        deployable = block["deployable"]
        if not deployable and not reasons:
            reasons = ("its validation says not deployable without a reason",)

        def number(key: str) -> float | None:
            v = block.get(key)
            return None if isinstance(v, bool) or not isinstance(v, (int, float)) else float(v)

        return cls(
            deployable,
            reasons,
            holdout_rms_mm=number("holdout_rms_mm"),
            holdout_max_mm=number("holdout_max_mm"),
            fit_rms_mm=number("fit_rms_mm"),
            nominal_rms_mm=number("nominal_rms_mm"),
            tolerance_mm=number("tolerance_mm"),
            noise_floor_mm=number("noise_floor_mm"),
            noise_floor_source=block.get("noise_floor_source"),
            condition_number=number("condition_number"),
            holdout=block.get("holdout"),
            summary=block.get("summary"),
            warnings=tuple(w for w in block.get("warnings") or () if isinstance(w, str)),
        )

    def refusal(self) -> str | None:
        """Why the model must not be deployed, in one line; None if it may be."""
        if self.deployable:
            return None
        return "the model is not deployable: " + "; ".join(self.reasons)
