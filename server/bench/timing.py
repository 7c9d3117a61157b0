"""Timing for the benchmarks: sides run in interleaved rounds, reported as medians with spread."""

from __future__ import annotations

import os
import time

import numpy as np


def spread(seconds) -> dict:
    """Median, quartiles and extremes of a list of times (s), and how many."""
    t = np.asarray(seconds, dtype=float)
    p25, p50, p75 = np.percentile(t, [25, 50, 75])
    return {
        "median_s": float(p50),
        "p25_s": float(p25),
        "p75_s": float(p75),
        "min_s": float(t.min()),
        "max_s": float(t.max()),
        "runs": len(t),
    }


def load() -> list[float]:
    """The 1, 5 and 15 minute load averages now."""
    return [round(v, 2) for v in os.getloadavg()]


def interleaved(fns: dict, rounds: int, budget_s: float = 120.0, limits: dict | None = None):
    """Run every callable once a round, for up to `rounds` rounds (at least 3 once budget_s is
    spent), the order rotating each round so that none always follows the same one.

    limits: name -> most rounds that callable takes part in (a slow secondary figure).
    Returns ({name: [seconds per round]}, {name: its last result}). Taking turns makes every
    side see the same machine: a slow spell on a shared host slows them all, not one.
    """
    limits = limits or {}
    names = list(fns)
    times: dict[str, list[float]] = {k: [] for k in names}
    results: dict = {}
    spent = 0.0
    for r in range(rounds):
        if r >= 3 and spent > budget_s:
            break
        for k in names[r % len(names) :] + names[: r % len(names)]:
            if len(times[k]) >= limits.get(k, rounds):
                continue
            t0 = time.perf_counter()
            results[k] = fns[k]()
            dt = time.perf_counter() - t0
            times[k].append(dt)
            spent += 0.0 if k in limits else dt  # a capped figure does not cut the others short
    return times, results


def paired(times: dict, num, den) -> dict:
    """Per-round ratios sum(times[num]) / sum(times[den]) over the rounds all of them ran:
    median, quartiles and extremes."""
    n = min(len(times[k]) for k in (*num, *den))
    ratio = np.array(
        [sum(times[k][i] for k in num) / sum(times[k][i] for k in den) for i in range(n)]
    )
    p25, p50, p75 = np.percentile(ratio, [25, 50, 75])
    return {
        "median": float(p50),
        "p25": float(p25),
        "p75": float(p75),
        "min": float(ratio.min()),
        "max": float(ratio.max()),
        "rounds": n,
    }
