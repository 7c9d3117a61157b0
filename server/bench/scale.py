"""The solvers and the meas.csv reader at scale (50,000 poses by default): wall time and peak
memory of ls-sum and minimax, and the file's reading time, each next to a reference measured in
the same run (ls-sum for minimax; numpy's loadtxt of the same numbers for the reader); and
planning's peak memory at 3 and 16 SMRs (linear in the SMRs since issue 20)."""

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


def peak_mb(fn) -> float:
    """Peak memory (MiB) that fn() allocates, as tracemalloc sees it (numpy reports there)."""
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


PLAN_SMRS = (3, 16)
PLAN_CANDIDATES, PLAN_POSES = 300, 10


def smr_ring(k: int) -> np.ndarray:
    """k SMRs (k, 3) mm on a 60 mm ring of the flange, slightly out of plane."""
    w = np.linspace(0.0, 2 * np.pi, k, endpoint=False)
    return np.column_stack([60 * np.cos(w), 60 * np.sin(w), 35 + 5 * np.sin(3 * w)])


def plan_at(smrs: int):
    """A D-optimal plan of PLAN_POSES of PLAN_CANDIDATES poses with `smrs` SMRs on the IRB
    2600, from its first run (the structural check's cache emptied): a function to measure."""
    from robocal.drivers.cell import VirtualCell
    from robocal.drivers.planning import plan_campaign
    from robocal.solver import identifiability
    from robocal.solver.robot import IRB2600

    from ..formats.cell_json import default_cell

    base = VirtualCell.random(IRB2600, default_cell().targets, seed=1).base
    targets = smr_ring(smrs)

    def plan():
        identifiability._structural.cache_clear()
        rng = np.random.default_rng(0)
        return plan_campaign(IRB2600, base, targets, PLAN_CANDIDATES, rng, k=PLAN_POSES)

    return plan


def run_planning() -> dict:
    """Planning's peak memory and time per SMR count; memory linear in the SMRs keeps the
    ratio of the largest to the smallest under the ratio of the counts."""
    out: dict = {"candidates": PLAN_CANDIDATES, "poses": PLAN_POSES}
    for smrs in PLAN_SMRS:
        seconds, _ = _timed(plan_at(smrs), 1)
        out[f"{smrs}_smrs"] = {"seconds": seconds, "peak_mb": peak_mb(plan_at(smrs))}
    lo, hi = out[f"{PLAN_SMRS[0]}_smrs"], out[f"{PLAN_SMRS[-1]}_smrs"]
    out["peak_mb_ratio"] = hi["peak_mb"] / lo["peak_mb"]
    out["linear_bound"] = PLAN_SMRS[-1] / PLAN_SMRS[0]
    return out


def run_scale(cell, meas, repeats: int = 2) -> dict:
    """ls-sum and minimax on the campaign (time, peak memory, their ratios), and its meas.csv
    read by robocal and by np.loadtxt."""
    from robocal.solver.calibrate import calibrate

    from ..formats.campaign_csv import joint_columns, read_campaign, write_campaign

    targets = cell.target_positions(meas.target_names)
    out: dict = {"poses": meas.n_poses, "readings": meas.n_readings}
    for method in ("ls-sum", "minimax"):

        def fit(method=method):
            return calibrate(
                cell.robot, targets, meas.target_names, meas.q, meas.xyz, method=method
            )

        seconds, cal = _timed(fit, repeats)
        out[method.replace("-", "_")] = {
            "seconds": seconds,
            "peak_mb": peak_mb(fit),
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
            "peak_mb": peak_mb(lambda: read_campaign(path, cell.robot)),
            "reference": "np.loadtxt of the numeric columns",
            "reference_seconds": ref,
            "ratio": ours / ref,
            "target_seconds": 0.3 if meas.n_poses <= 50_000 else None,
        }
    out["planning"] = run_planning()
    return out


DIAGNOSE_POSES = (1_000, 3_000, 10_000)
DIAGNOSE_TARGETS = {"seconds_ratio_10x_poses": 10.0, "peak_rss_mib": 1024.0}  # issue 24


def peak_rss_mib() -> float:
    """This process's peak resident memory, MiB: Linux's VmHWM, which starts afresh at exec
    (ru_maxrss keeps the peak of the process that forked it)."""
    import resource

    status = Path("/proc/self/status")
    if status.exists():
        for line in status.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def diagnose_at(poses: int, seed: int = 0) -> dict:
    """One diagnosis of the timed campaign of `poses` written to meas.csv and read back, in this
    process: wall and CPU time, the process's peak RSS, and np.loadtxt of the same file."""
    from robocal.solver.diagnose import diagnose

    from ..formats.campaign_csv import joint_columns, read_campaign, write_campaign
    from .diagnose import timed_campaign

    cell, meas = timed_campaign(poses, seed)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "meas.csv"
        write_campaign(path, meas)
        n = len(joint_columns(cell.robot))
        numeric = [*range(1, n + 1), n + 2, n + 3, n + 4]
        ref, _ = _timed(
            lambda: np.loadtxt(path, delimiter=",", skiprows=1, usecols=numeric), repeats=3
        )
        read = read_campaign(path, cell.robot)
    targets = cell.target_positions(read.target_names)
    before = peak_rss_mib()
    t0, c0 = time.perf_counter(), time.process_time()
    diagnose(cell.robot, targets, read.target_names, read.q, read.xyz, read.time_s, read.temp_c)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {
        "poses": poses,
        "seconds": seconds,
        "cpu_seconds": cpu,
        "ms_per_pose": 1e3 * seconds / poses,
        "peak_rss_mib": peak_rss_mib(),
        "rss_before_diagnosis_mib": before,
        "loadtxt_seconds": ref,
        "over_loadtxt": seconds / ref,
    }


def run_diagnose_scale(sizes=DIAGNOSE_POSES, seed: int = 0) -> dict:
    """diagnose_at each size, each in a fresh process (its peak RSS is that diagnosis's), and
    the largest size's time and memory against the smallest's."""
    import multiprocessing

    out: dict = {"reference": "np.loadtxt of the numeric columns of the same meas.csv"}
    for poses in sizes:
        with multiprocessing.get_context("spawn").Pool(1) as pool:
            out[str(poses)] = pool.apply(diagnose_at, (poses, seed))
    lo, hi = out[str(min(sizes))], out[str(max(sizes))]
    ratio = max(sizes) / min(sizes)
    out["largest_over_smallest"] = {
        "poses": ratio,
        "seconds": hi["seconds"] / lo["seconds"],
        "cpu_seconds": hi["cpu_seconds"] / lo["cpu_seconds"],
        "peak_rss_mib": hi["peak_rss_mib"] / lo["peak_rss_mib"],
    }
    out["targets"] = DIAGNOSE_TARGETS
    out["met"] = {
        "seconds_linear": hi["seconds"] / lo["seconds"]
        <= DIAGNOSE_TARGETS["seconds_ratio_10x_poses"] * ratio / 10,
        "peak_rss_under_1_gib": hi["peak_rss_mib"] < DIAGNOSE_TARGETS["peak_rss_mib"],
    }
    return out
