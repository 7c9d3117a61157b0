"""The solvers and the meas.csv reader at scale (50,000 poses by default): wall time and peak
memory of ls-sum and minimax, and the file's reading time, each next to a reference measured in
the same run (ls-sum for minimax; numpy's loadtxt of the same numbers for the reader)."""

from __future__ import annotations

import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np


def _timed(fn, repeats: int) -> tuple[float, Any]:
    """The fastest of `repeats` runs of fn() and its last result."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _peak_mb(fn) -> float:
    """Peak memory (MiB) that fn() allocates, as tracemalloc sees it (numpy reports there)."""
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def run_scale(cell, meas, repeats: int = 2) -> dict:
    """ls-sum and minimax on the campaign (time, peak memory, their ratios), and its meas.csv
    read by robocal and by np.loadtxt."""
    from robocal.solver.calibrate import calibrate

    from .formats.campaign_csv import joint_columns, read_campaign, write_campaign

    targets = np.array([cell.targets[t] for t in meas.target_names], dtype=float)
    out: dict = {"poses": meas.n_poses, "readings": meas.n_readings}
    for method in ("ls-sum", "minimax"):

        def fit(method=method):
            return calibrate(
                cell.robot, targets, meas.target_names, meas.q, meas.xyz, method=method
            )

        seconds, cal = _timed(fit, repeats)
        out[method.replace("-", "_")] = {
            "seconds": seconds,
            "peak_mb": _peak_mb(fit),
            "objective": float(cal.F.max() if method == "minimax" else cal.F.sum()),
        }
    ls, mm = out["ls_sum"], out["minimax"]
    out["minimax_over_ls_sum"] = {
        "seconds": mm["seconds"] / ls["seconds"],
        "peak_mb": mm["peak_mb"] / ls["peak_mb"],
        "targets": {"seconds": 4.0, "peak_mb": 1.5},
    }
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "meas.csv"
        write_campaign(path, meas)
        n = len(joint_columns(cell.robot))  # pose, q1..qn, target, x, y, z
        numeric = [*range(1, n + 1), n + 2, n + 3, n + 4]
        ours, _ = _timed(lambda: read_campaign(path, cell.robot), repeats + 1)
        ref, _ = _timed(
            lambda: np.loadtxt(path, delimiter=",", skiprows=1, usecols=numeric), repeats + 1
        )
        out["meas_csv"] = {
            "bytes": path.stat().st_size,
            "rows": meas.n_readings,
            "read_seconds": ours,
            "peak_mb": _peak_mb(lambda: read_campaign(path, cell.robot)),
            "reference": "np.loadtxt of the numeric columns",
            "reference_seconds": ref,
            "ratio": ours / ref,
            "target_seconds": 0.3 if meas.n_poses <= 50_000 else None,
        }
    return out
