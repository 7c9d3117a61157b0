"""What a run of acquire() did: the typed result its callers read (the CLI, the service, the
verification and check runs, the benchmarks)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

from robocal.drivers.engine_settings import PhaseSeconds

if TYPE_CHECKING:
    from robocal.server.acquisition.adaptive_plan import AdaptiveSummary


@dataclass(frozen=True)
class AcquireSummary:
    """A campaign's run: the state it ended in, what it measured, the campaign clock's time."""

    campaign: int  # the campaign's id in the store
    name: str
    resumed_at: int | None  # the pose index it resumed at; None: a new campaign
    poses: int  # poses planned
    state: str  # the engine's state at the end: done, paused, stopped...
    measured_poses: int  # by this run
    readings: int
    missing: int
    beam_breaks: int
    searched: int
    locked_without_search_after_10: float | None  # share of re-aims locked at once after pose 10
    campaign_s: float | None  # campaign clock seconds of a new campaign; None for a resumed one
    campaign_end_s: float
    predictor: str  # the SMR predictor's stage at the end
    skipped_poses: int
    phase_s: PhaseSeconds  # campaign clock seconds per kind of plan message (this run's)
    simulated: bool
    adaptive: AdaptiveSummary | None  # an adaptive campaign's steps (acquisition.adaptive)

    def to_json(self) -> dict[str, Any]:
        """The summary as the service stores and answers it, keys in the fields' order."""
        out = asdict(self)
        out["adaptive"] = None if self.adaptive is None else self.adaptive.to_json()
        return out
