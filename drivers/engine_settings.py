"""How the campaign engine acquires (Settings: the paper's fixed pause by default, or adaptive
settling) and what it counted while it did (Stats)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Settings:
    """How to acquire: the paper's procedure by default (fixed 10 s pause at each pose)."""

    pause_s: float = 10.0
    # or "adaptive": every reading is the first still window of the tracker's sample stream
    # (STABLE), or, on a tracker without it, ends the pause once looks see the first SMR still
    settle: str = "fixed"
    # readings of a still SMR differ by noise alone: about 3 sqrt(2) times a tracker's per-axis
    # repeatability at a few metres
    settle_tol_mm: float = 0.03
    # adaptive settling watches the first SMR in back-to-back looks of this many samples (50 ms
    # at 1 kHz, a fraction of an arm's ringing period) and calls it still once this many
    # successive looks, each with a spread the tracker calls OK, agree within settle_tol_mm
    settle_look_samples: int = 50
    settle_looks: int = 3
    # the tracker's head slew (POINT): issued this long before a move's expected end, at the
    # first SMR's predicted position, the beam is there as the arm arrives
    point_lead_s: float = 0.05
    samples: int = 1000
    search_radius_mm: float = 10.0
    wide_search_radius_mm: float = 50.0
    retries: int = 2  # per target, after a beam break or a failed search

    def __post_init__(self):
        if self.settle not in ("fixed", "adaptive"):
            raise ValueError(f"settle must be 'fixed' or 'adaptive', not {self.settle!r}")


@dataclass
class PhaseSeconds:
    """Campaign clock seconds spent in each kind of plan message (where a campaign's time goes)."""

    move: float = 0.0  # the move, the beam pointed ahead, the arm reported in position
    settle: float = 0.0  # a fixed pause, or looks (adaptive on a tracker without a stream)
    aim: float = 0.0  # POINTs and searches at the arrived pose
    measure: float = 0.0  # readings with their retries (the stream's wait for a still window)
    other: float = 0.0  # checkpoints (a pause's wait) and saves


@dataclass
class Stats:
    """What happened: counts a person and the benchmark care about."""

    poses: int = 0
    readings: int = 0
    missing: int = 0
    skipped: int = 0
    searched: int = 0
    locked_first_try: int = 0
    aimed: int = 0
    beam_breaks: int = 0
    aimed_after_10: int = 0
    locked_after_10: int = 0
    settle_s: list = field(default_factory=list)
    phase_s: PhaseSeconds = field(default_factory=PhaseSeconds)
