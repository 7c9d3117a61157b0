"""Why an iterative fit stopped, as the code model.json keeps (`status`), set where it stops."""

from __future__ import annotations

from enum import IntEnum


class Stop(IntEnum):
    """0 converged, 1 iteration limit, 2 stopped without converging (no descent, an unsolved
    subproblem)."""

    CONVERGED = 0
    ITERATION_LIMIT = 1
    OTHER = 2
