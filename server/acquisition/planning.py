"""Planning a campaign for the API: its size bounded up front, and which plans take long enough
(a D-optimal choice, a long tour) to run as a planning job (Jobs.submit_planning) rather than in
the request, so an oversized plan is refused at once and none can hold the service."""

from __future__ import annotations

from robocal.server.acquisition.acquire import AcquireOptions

# The D-optimal exchange costs about poses x candidates x parameters; at these bounds it plans
# in a few seconds (20 of 2000 candidates: 3 s on a busy two-core machine).
MAX_CANDIDATES = 2000
MAX_CHOICE_WORK = 40_000  # poses x candidates


# Above this many poses, ordering them (a shortest-path tour) takes seconds.
ORDER_INLINE_POSES = 500


class PlanTooLarge(ValueError):
    """A plan whose planning would take too long for a request; names the fields."""


def check_plan_size(opts: AcquireOptions) -> None:
    """PlanTooLarge unless the D-optimal choice fits the bounds above."""
    if not opts.choose_from:
        return
    if opts.choose_from > MAX_CANDIDATES:
        raise PlanTooLarge(
            f"choose_from: {opts.choose_from} candidates is more than the "
            f"{MAX_CANDIDATES} a plan may choose from"
        )
    if opts.poses * opts.choose_from > MAX_CHOICE_WORK:
        raise PlanTooLarge(
            f"poses x choose_from: {opts.poses} x {opts.choose_from} is more than "
            f"{MAX_CHOICE_WORK}; choose fewer poses or from fewer candidates"
        )


def plans_long(opts: AcquireOptions) -> bool:
    """Whether planning may take seconds (a D-optimal choice, a long tour): then as a job;
    random poses alone plan in well under a second, in the request."""
    return bool(opts.choose_from) or (opts.order and opts.poses > ORDER_INLINE_POSES)
