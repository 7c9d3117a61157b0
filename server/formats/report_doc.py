"""The shape of `report.json` (spec section 5) as pydantic models; readers ignore unknown keys."""

from __future__ import annotations

from typing import TYPE_CHECKING

from pydantic import ConfigDict, Field

from robocal.solver.vocabulary import KINDS

from .blocks import Figure, Identified, Ordered, Score, Unexplained, Validation

if TYPE_CHECKING:
    from robocal.solver.diagnose import Diagnosis


class Open(Ordered):
    """A report object: what a writer adds beyond the spec's keys is kept, in its order."""


class Alternative(Open):
    name: str
    label: str = Field(description="as the report names effects: joint_periodic(3, harmonic 2)")
    holdout_rmse_mm: float


class WholeEffect(Open):
    """An effect the model deploys at half its fitted size (`stability.half_way`), as the
    selection judged it: fitted whole."""

    holdout_rmse_before_mm: float
    holdout_rmse_after_mm: float = Field(
        description="the model with the effect whole: the figure that selected it"
    )
    holdout_max_before_mm: float | None = None
    holdout_max_after_mm: float | None = None
    holdout_gain_interval_mm: list[float] | None = Field(None, min_length=2, max_length=2)
    parameters: dict[str, Figure | list[Figure] | str | None] = Field(
        description="the effect's parameters at its whole fitted size"
    )
    uncertainty: dict[str, Figure | list[Figure] | None] | None = Field(
        None, description="their standard errors, the extended fit's own"
    )


class Effect(Open):
    """An effect judged real, with the held-out evidence for it. Every figure is the deployed
    model's: with the model half way (`stability.half_way`), the held-out figures are the
    half-way model's up to this effect, the parameters the effect at half its fitted size with
    that model's standard errors, and the selection's evidence (the effect whole) `whole_effect`.
    """

    def key(self) -> tuple[str, int | None, int | None]:
        """(name, joint from 1, harmonic): which effect it is, as a model's extension says."""
        return self.name, self.joint, self.harmonic

    name: str = Field(json_schema_extra={"enum": list(KINDS)})
    joint: int | None = Field(None, ge=1, description="joints are numbered from 1")
    harmonic: int | None = Field(None, description="joint_periodic's multiple of the angle")
    at_s: float | None = Field(None, description="base_shift's time, s")
    evidence: str = Field(description="one sentence a person can check")
    holdout_rmse_before_mm: float
    holdout_rmse_after_mm: float
    # as written (an int count stays an int when printed; thermal drift names its driver)
    parameters: dict[str, Figure | list[Figure] | str | None]
    uncertainty: dict[str, Figure | list[Figure] | None] | None = Field(
        None, description="each parameter's standard error"
    )
    holdout_gain_interval_mm: list[float] | None = Field(None, min_length=2, max_length=2)
    alternatives: list[Alternative] | None = Field(
        None, description="candidates the data could not tell apart from it"
    )
    whole_effect: WholeEffect | None = Field(
        None,
        description="when the model deploys the effect half way (`stability.half_way`): the "
        "effect fitted whole, as the selection judged it (its held-out figures, gain interval, "
        "parameters and their standard errors); absent otherwise",
    )


class Outlier(Open):
    """A reading excluded as a gross error (solver.screen.Outlier)."""

    pose: str | int
    target: str
    residual_mm: float
    evidence: str | None = Field(
        None, description="which evidence judged it: `distance`, `within-pose` or `geometric`"
    )


class RegionFold(Open):
    test: str = Field(
        description="the test poses' side of the split, e.g. `q2 >= 12.3 deg` or `wrist: q5 < 0`"
    )
    test_poses: int
    beyond_training_deg: float = Field(
        description="how far the test poses reach past the training poses' range of that joint "
        "(a configuration fold: of the joint reaching furthest)"
    )
    geometric_rmse_mm: float | None
    final_rmse_mm: float | None
    worse_only_in_geometric_span: bool = Field(
        False,
        description="the final model is over max_ratio_to_geometric here, but only inside the "
        "span of the test poses' geometric Jacobian (geometric parameters fitted on one region, "
        "which a fit on the whole campaign refits): no worse than geometry outside it, and moving "
        "the prediction there by less than geometry's own error there plus what the effect "
        "gained outside, its relative gain outside outweighing its relative loss inside; not "
        "refused for it",
    )


class Refused(Open):
    name: str
    label: str
    joint: int | None = None
    worse_on: list[str] = Field(description="the region folds it made worse than geometry")
    reason: str | None = Field(
        None,
        description="why it was refused, in a sentence: worse than geometry on region folds, "
        "terms that turn their joint by more than any gear or compliance error can, or a "
        "compliance whose fitted link masses reverse the sign of its stiffness",
    )


class Extrapolation(Open):
    method: str
    max_ratio_to_geometric: float
    folds: list[RegionFold]
    refused: list[Refused] = Field(
        description="effects the random folds accepted that did not hold off the training region"
    )
    joint_range_deg: list[list[float]] = Field(
        description="per joint, the [min, max] the data covers: the model is trusted within it"
    )


class ResampledEffect(Open):
    effect: str = Field(description="e.g. `joint_compliance(2)`, `joint_periodic(3, harmonic 2)`")
    named_in: int = Field(description="how many resamples named it")
    in_final: bool = Field(description="whether the final model has it")


class Stability(Open):
    resamples: int
    poses_each: int
    named_nothing: int = Field(description="resamples that named no effect (fewer poses)")
    agreeing: int | None = Field(
        None, description="resamples that named a cause the final model has"
    )
    effects: list[ResampledEffect]
    doubt: str | None = Field(
        description="when no more than half the resamples name a cause of the final model (one "
        "naming nothing or another cause counts against it), or another cause is named on two "
        "or more, in a sentence; null otherwise"
    )
    replaced: list[str] | None = Field(
        None,
        description="the whole campaign's causes, each named on one resample at most, given up "
        "for the cause a majority of the resamples name: the final model has that cause when "
        "the selection on all the poses accepts it alone, else no effect (the geometric model; "
        "the effects suspected, not in it); null when the campaign's own answer stands",
    )
    agreed: str | None = Field(
        None, description="that replacement and the model it leaves, in a sentence"
    )
    half_way: str | None = Field(
        None,
        description="when the final model's held-out gain over geometry is weak (under 15 % of "
        "geometry's RMS), the model deployed is half way between geometry and the extended fit "
        "(parameters averaged, the effects at half their fitted size), said in a sentence; "
        "null otherwise. Every figure of the report is then that model's: `final`, each "
        "effect's held-out figures, gain interval, parameters and standard errors (the "
        "effects' coefficients' are half the extended fit's; an averaged parameter's carry the "
        "two fits' cross-covariance, model.json's `uncertainty.estimator` says so); what the "
        "selection judged is each effect's `whole_effect`",
    )
    held: list[str] | None = Field(
        None,
        description="per joint scale or periodic term held to the joint range the campaign "
        "covered (its value at the range's edge beyond it; model.json's `held_range_deg`): "
        "look-alikes on its joint that the data cannot tell from it part past that range by "
        "more than the final held-out RMS, in a sentence each; null when none is held",
    )


class Seconds(Open):
    total: float = Field(description="the whole diagnosis, s (its phases beside it)")


class ReportDoc(Open):
    """A report.json: what the diagnosis found, most important effect first."""

    model_config = ConfigDict(title="report.json")
    schema_: int = Field(1, alias="schema")
    noise_floor_mm: float
    noise_floor_source: str | None = Field(
        None,
        description="where the floor comes from: SMR-to-SMR distances or repeated readings in "
        "the data, else the cell's tracker specification (or the default one, said so)",
    )
    baseline: Score
    effects: list[Effect] = Field(description="effects judged real, most important first")
    final: Score
    outliers: list[Outlier] | None = Field(None, description="readings excluded as gross errors")
    unexplained: Unexplained | None = None
    seconds: Seconds | None = Field(None, description="where the diagnosis's time went")
    extrapolation: Extrapolation | None = Field(
        None,
        description="the final model tested off its training region: trained on one side of "
        "each gravity-loaded joint's median (of every joint moving an SMR where gravity loads "
        "none, a SCARA's; of any other joint for that joint's own effects; a "
        "smaller end on a small campaign), or in one elbow or "
        "wrist configuration where the data has both, tested on the other; an effect that made "
        "any such "
        "fold worse than geometry is refused",
    )
    stability: Stability | None = Field(
        None,
        description="small campaigns (40 poses or fewer) that name an effect: the diagnosis "
        "repeated on resamples leaving out every fifth pose, the effects each named, and the "
        "doubt when no more than half name a cause of the final model, or another cause is "
        "named on two or more",
    )
    identified: Identified | None = Field(
        None,
        description="the final model's identified parameters, as model.json's `identified` "
        "(per parameter: change from nominal and standard error; held-fixed parameters and "
        "why; shrunk ones with their share from the data and the prior they were fitted "
        "under; condition number; strongest correlations)",
    )
    validation: Validation | None = Field(
        None,
        description="whether the data supports the final model, as model.json's `validation` "
        "(`deployable`, `reasons`, the cross-validated held-out RMS beside the fit RMS)",
    )

    @classmethod
    def of(cls, diagnosis: Diagnosis) -> ReportDoc:
        """The solver's diagnosis report, typed once (numpy figures made JSON's numbers)."""
        from .model_json import to_plain

        return cls.model_validate(to_plain(diagnosis.report.to_json()))
