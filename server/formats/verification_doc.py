"""The shape of `verification.json` (an ISO 9283 run before and after compensation) as pydantic
documents: `acquire --verify` writes it, the API answers it, the table and the certificate read
it; keys kept in the order the run gives them."""

from __future__ import annotations

import datetime as dt
from typing import Any, ClassVar

from pydantic import ConfigDict, Field

from .blocks import Figure, ModelQuote, Ordered


class PointFigures(Ordered):
    """One test point's ISO 9283 figures in one run, mm."""

    point: str
    commanded_mm: list[Figure]
    AP_mm: Figure
    AP_xyz_mm: list[Figure]
    RP_mm: Figure
    # written since RP's U (solver.repeatability): absent from older files
    RP_U_below_mm: Figure | None = Field(None, description="U of the RP below the figure")
    RP_U_above_mm: Figure | None = Field(None, description="U of the RP above the figure")
    vAP_mm: Figure
    attained_mm: list[list[Figure]] = Field(description="per visit (cycle x direction), x y z")
    AP_U_mm: Figure | None = Field(None, description="U of the AP (the compensated run's)")


class Distance(Ordered):
    """Distance accuracy and repeatability of a pair of test points, mm."""

    pair: list[str]
    AD_mm: Figure
    RD_mm: Figure


class RunFigures(Ordered):
    """One run's figures (the nominal joints' or the compensated ones'), mm."""

    points: list[PointFigures]
    AP_max_mm: Figure
    RP_max_mm: Figure
    distances: list[Distance] = Field([], description="none when the points make no pair")


class VerifiedModel(Ordered):
    """The model verified: its file, digest and what the record quotes of its blocks."""

    path: str
    sha256: str
    # as the campaign's record stored it (its keys in the store's order)
    meta: dict[str, Any] | None = None

    def quote(self) -> ModelQuote:
        """What the record quotes of the model's diagnosis and verdict."""
        return ModelQuote.model_validate(self.meta or {})


class Instrument(Ordered):
    """The tracker: its kind and spec (simulated) or address, and its traceability."""

    kind: str = "laser tracker"
    serial: str | None = None
    certificate_id: str | None = None
    certificate_due: dt.date | str | None = None
    smr_ids: dict[str, str] | None = None

    # the traceability keys, which the certificate lists on lines of their own
    TRACEABILITY: ClassVar[tuple[str, ...]] = (
        "kind",
        "smr_ids",
        "certificate_id",
        "certificate_due",
        "serial",
    )

    def description(self) -> str:
        """The kind, then every other figure given (mpe_um 10.0, address host:port...)."""
        return self.kind + "".join(
            f", {k} {v}"
            for k, v in self.to_json().items()
            if k not in self.TRACEABILITY and v is not None
        )


class VolumeMap(Ordered):
    xyz_mm: list[list[Figure]]
    U_mm: list[Figure]


class ModelU(Ordered):
    """The model's U (95 %) at each test point, itself and as a reading would find it."""

    coverage: Figure
    map: VolumeMap | None = None
    model_U_mm: list[Figure]
    reading_U_mm: list[Figure]
    k: list[Figure]
    joint_scatter_deg: Figure


class Decision(Ordered):
    """Pass, fail or not decided against the tolerance (ISO 14253-1 guard bands): pass only when
    every point's figure plus its U (above) is within it, fail when any point's figure less its
    U (below) is beyond it, otherwise not decided; never pass with the tracker overdue."""

    verdict: str = Field(
        description="pass, fail, not decided (as well: a pass with the tracker overdue) or no "
        "tolerance (none given)"
    )
    tracker_overdue: dt.date | str | None = Field(
        None, description="the tracker's calibration due date when the run was after it"
    )
    tolerance_mm: Figure | None = Field(
        None, description="what the figures are decided against, mm; null: not given"
    )
    rule: str = Field(description="the decision rule, as a sentence")
    worst_upper_mm: Figure = Field(description="the largest figure plus its U (above), mm")
    worst_lower_mm: Figure = Field(description="the largest figure less its U (below), mm")


class VerificationUncertainty(Ordered):
    """The model's U at the test points, the figures' U (how stated) and the decisions on them."""

    model: ModelU | None = Field(
        None, description="the model's U at the test points; null for a model without it"
    )
    # written since U at the visits' time and temperature: absent from older files
    model_note: str | None = Field(
        None,
        description="where the model's extensions need a pose's time or temperature: at which "
        "inputs its U was taken, or why it is not given",
    )
    # written since the temperature terms are compensated during the run: absent from older files
    compensation_note: str | None = Field(
        None,
        description="where the model's temperature terms were compensated as each pose was due: "
        "how many poses were compensated without them, the cell having reported no temperature, "
        "and how many at an earlier reading's temperature (the weather station giving none as "
        "they were due) and how old the oldest was",
    )
    ap_u: str = Field("", description="how each AP's U is stated")
    decision: Decision | None = Field(
        None,
        description="the compensated APs with their U against the tolerance: the cell's "
        "tolerance_mm, else the one the model's validation quotes",
    )
    # written since RP's U: absent from older files
    rp_u: str | None = Field(None, description="how each RP's U below and above is stated")
    rp_decision: Decision | None = Field(
        None,
        description="the compensated RPs against the arm's stated repeatability, the cell's "
        "repeatability_mm: pass when every RP plus its U above is within it, fail when an RP "
        "less its U below is beyond it, else not decided (no tolerance without the key)",
    )


class VerificationDoc(Ordered):
    """A verification.json: the run's setting and its ISO 9283 figures before and after."""

    model_config = ConfigDict(title="verification.json")

    robot: str
    model: VerifiedModel
    instrument: Instrument
    date: str = Field(description="UTC, ISO 8601")
    smr: str
    simulated: bool
    campaign: int
    cycles: int
    directions: int
    approach_mm: Figure
    points: list[str]
    before: RunFigures
    after: RunFigures
    simulated_s: dict[str, Figure | None] | None = None
    tracker_overdue: dt.date | str | None = Field(
        None, description="the tracker's calibration due date when the run was after it: no pass"
    )
    uncertainty: VerificationUncertainty | None = None
