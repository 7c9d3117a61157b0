"""A campaign's life cycle: its states, the requests and events that move it, one table.

The engine owns the state of a running campaign and moves it only through this table; the store
persists what the engine says, and the API reports the state with the actions it allows. Nothing
else invents states.
"""

from __future__ import annotations

STATES = (
    "planned",
    "running",
    "pausing",
    "paused",
    "stopping",
    "aborted",
    "estopped",
    "failed",
    "done",
)
# What a person or the API may ask for, in the order a user interface shows them.
ACTIONS = ("start", "pause", "resume", "abort", "estop", "reset")
# What only the engine reports: it reached a pause or an abort between poses, ran out of poses,
# or met a device fault.
EVENTS = ("paused", "stopped", "finish", "fail")
FINAL = ("aborted", "done")

# state -> {request or event: next state}
TRANSITIONS: dict[str, dict[str, str]] = {
    "planned": {"start": "running", "abort": "aborted"},
    "running": {
        "pause": "pausing",
        "abort": "stopping",
        "estop": "estopped",
        "finish": "done",
        "fail": "failed",
    },
    # resume before the pause is reached cancels it: no request is lost in between
    "pausing": {
        "resume": "running",
        "abort": "stopping",
        "estop": "estopped",
        "paused": "paused",
        "finish": "done",
        "fail": "failed",
    },
    "paused": {"resume": "running", "abort": "aborted", "estop": "estopped"},
    "stopping": {"estop": "estopped", "stopped": "aborted", "finish": "done", "fail": "failed"},
    # an e-stop latches: the arm moves again only after an explicit reset (then paused, resumable)
    "estopped": {"estop": "estopped", "reset": "paused", "abort": "aborted"},
    "failed": {"resume": "running", "reset": "paused", "abort": "aborted"},
    "aborted": {},
    "done": {},
}
# The states in which the arm may be moving under the engine's command.
MOVING = ("running", "pausing", "stopping")


class StateError(RuntimeError):
    """A request the campaign's state does not allow; says the state and what it allows."""

    def __init__(self, state: str, action: str, campaign: str = "campaign"):
        self.state, self.action, self.allowed = state, action, allowed(state)
        can = ", ".join(self.allowed) or "nothing (it is final)"
        super().__init__(f"cannot {action} a {campaign} that is {state}; it allows {can}")


def allowed(state: str) -> list[str]:
    """The user actions legal in `state`, in ACTIONS order."""
    return [a for a in ACTIONS if a in TRANSITIONS[state]]


def next_state(state: str, request: str, campaign: str = "campaign") -> str:
    """Where `request` (an action or an engine event) leads from `state`; StateError if nowhere."""
    if state not in TRANSITIONS:
        raise ValueError(f"unknown campaign state {state!r}")
    nxt = TRANSITIONS[state].get(request)
    if nxt is None:
        raise StateError(state, request, campaign)
    return nxt


def reachable(state: str, target: str) -> bool:
    """True if one request or event leads from `state` to `target` (or it is the same state)."""
    return state == target or target in TRANSITIONS[state].values()
