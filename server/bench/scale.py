"""The solvers and the meas.csv reader at scale (50,000 poses by default): wall time and peak
memory of ls-sum and minimax, and the file's reading time, each next to a reference measured in
the same run (ls-sum for minimax; numpy's loadtxt of the same numbers for the reader); and
planning's peak memory at 3 and 16 SMRs (linear in the SMRs since issue 20).

`robocal bench scale` (run_calibrate_scale): the whole `robocal calibrate` of a large campaign,
its wall time and peak memory as a process, next to a process that only np.loadtxt's the same
file and one that only reads and fits it, in interleaved rounds (issue 24)."""

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
    from robocal.solver.problem import Problem

    from ..formats.campaign_csv import joint_columns, read_campaign, write_campaign

    problem = Problem.of(cell.robot, cell.target_positions(meas.target_names), meas)
    out: dict = {"poses": meas.n_poses, "readings": meas.n_readings}
    for method in ("ls-sum", "minimax"):

        def fit(method=method):
            return calibrate(problem, method)

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


# issue 24's targets: the whole command within these multiples of its references
CALIBRATE_OVER_LOADTXT_MAX = 6.0  # wall time, against a process that only loadtxt's the file
CALIBRATE_OVER_FIT_MEMORY_MAX = 1.5  # peak memory, against the fit's own


def _numeric_columns(robot) -> list[int]:
    """meas.csv's numeric columns as write_campaign orders them: q1..qn, then x, y, z."""
    from ..formats.campaign_csv import joint_columns

    n = len(joint_columns(robot))  # pose, q1..qn, target, x, y, z, ...
    return [*range(1, n + 1), n + 2, n + 3, n + 4]


# Started by a small launcher: on Linux a process's peak resident set counts the memory of the
# process it was forked from (kept across exec), so the benchmark's own would mask the command's.
_LAUNCH = """
import os, sys, time
t0 = time.perf_counter()
pid = os.fork()
if pid == 0:
    os.execvp(sys.argv[2], sys.argv[2:])
_, status, usage = os.wait4(pid, 0)
wall = time.perf_counter() - t0
with open(sys.argv[1], "w") as f:
    f.write(f"{os.waitstatus_to_exitcode(status)} {wall} {usage.ru_maxrss}")
"""


def _process(argv, cwd) -> tuple[float, float]:
    """Wall time (s) and peak resident memory (MiB) of one process, from its own rusage."""
    import subprocess
    import sys

    with tempfile.TemporaryDirectory() as tmp:
        out, err = Path(tmp) / "usage", Path(tmp) / "stderr"
        with open(err, "wb") as stderr:
            subprocess.run(
                [sys.executable, "-c", _LAUNCH, str(out), *map(str, argv)],
                cwd=cwd,
                stdout=subprocess.DEVNULL,
                stderr=stderr,
                check=False,
            )
        code, wall, maxrss = out.read_text().split()
        if int(code) != 0:
            why = err.read_text(errors="replace").strip()[-1000:]
            raise RuntimeError(f"{' '.join(map(str, argv))} failed: {why}")
    return float(wall), int(maxrss) / 1024  # Linux: KiB


def _summary(values: list[float]) -> dict:
    """Median and spread of repeated figures."""
    import statistics

    return {
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
        "runs": [round(v, 4) for v in values],
    }


_FIT_ONLY = """
import sys
from robocal.server.calibration import workflow
cell, meas = workflow.load_data(sys.argv[1])
workflow.run_method(cell, meas, "ls-sum", screening=False)
"""


def _in_process(path: Path) -> dict:
    """Peak memory (tracemalloc, MiB) of the fit alone and of the whole command's work in this
    process (read, fit, model file with standard errors and validation), with the fit's and the
    post-fit's share of the time."""
    from robocal.server.calibration import workflow

    cell = workflow.load_cell(None)
    meas = workflow.load_campaign(path, cell)
    fit_peak = peak_mb(lambda: workflow.run_method(cell, meas, "ls-sum", screening=False))

    def whole():
        c, m = workflow.load_data(path)
        cal = workflow.run_method(c, m, "ls-sum", screening=False)
        workflow.model_file(cal, c, m, data_path=path)

    whole_peak = peak_mb(whole)
    read_peak = peak_mb(lambda: workflow.load_data(path))
    t0 = time.perf_counter()
    cal = workflow.run_method(cell, meas, "ls-sum", screening=False)
    t1 = time.perf_counter()
    workflow.model_file(cal, cell, meas, data_path=path)
    t2 = time.perf_counter()
    return {
        "fit_peak_mb": fit_peak,
        "read_peak_mb": read_peak,
        "calibrate_peak_mb": whole_peak,
        "calibrate_over_fit": whole_peak / fit_peak,
        "fit_seconds": t1 - t0,
        "model_file_seconds": t2 - t1,
    }


def run_calibrate_scale(poses: int = 50_000, repeats: int = 5, seed: int = 0) -> dict:
    """`robocal calibrate --method ls-sum --keep-outliers` of a simulated campaign of `poses`
    poses as a process, in rounds with a process that only np.loadtxt's the file's numeric
    columns and one that only reads and fits it (the order rotating each round): medians,
    spread and the load average; then in-process peak memory (tracemalloc) of the fit and of
    the whole command, and np.loadtxt against robocal's reader in the same process."""
    import os
    import sys

    from ..formats.campaign_csv import read_campaign, write_campaign
    from ..formats.cell_json import default_cell
    from .solver import _campaign, _machine
    from .startup import robocal_argv

    cell = default_cell()
    meas = _campaign(cell, poses, seed)
    cols = _numeric_columns(cell.robot)
    load = [os.getloadavg()]
    with tempfile.TemporaryDirectory(prefix="robocal-bench-scale-") as tmp:
        work = Path(tmp)
        path = work / "meas.csv"
        write_campaign(path, meas)
        loadtxt = f"import numpy as np; np.loadtxt({str(path)!r}, delimiter=',', skiprows=1, usecols={cols})"
        commands = {
            "calibrate": [
                *robocal_argv(),
                *("calibrate", path.name, "--method", "ls-sum", "--keep-outliers"),
                *("--out", "model.json"),
            ],
            "loadtxt": [sys.executable, "-c", loadtxt],
            "fit_only": [sys.executable, "-c", _FIT_ONLY, path.name],
        }
        wall: dict[str, list[float]] = {k: [] for k in commands}
        rss: dict[str, list[float]] = {k: [] for k in commands}
        names = list(commands)
        for r in range(repeats):
            for k in names[r % len(names) :] + names[: r % len(names)]:  # rotate who goes first
                w, m = _process(commands[k], work)
                wall[k].append(w)
                rss[k].append(m)
        load.append(os.getloadavg())
        reader, ref = [], []
        for _ in range(repeats + 2):
            t0 = time.perf_counter()
            read_campaign(path, cell.robot)
            t1 = time.perf_counter()
            np.loadtxt(path, delimiter=",", skiprows=1, usecols=cols)
            t2 = time.perf_counter()
            reader.append(t1 - t0)
            ref.append(t2 - t1)
        inside = _in_process(path)
        size = path.stat().st_size
    load.append(os.getloadavg())
    med = {k: _summary(v)["median"] for k, v in wall.items()}
    peak = {k: _summary(v)["median"] for k, v in rss.items()}
    return {
        "benchmark": "scale",
        "machine": _machine(),
        "poses": meas.n_poses,
        "readings": meas.n_readings,
        "file_bytes": size,
        "repeats": repeats,
        "timing": "fresh processes in rounds, the order rotating each round; wall time from "
        "start to exit, peak memory the process's maximum resident set (getrusage); medians "
        "with min, max and every run",
        "load_average_1_5_15": {"start": load[0], "after_processes": load[1], "end": load[2]},
        "process": {
            k: {"wall_seconds": _summary(wall[k]), "peak_rss_mb": _summary(rss[k])}
            for k in commands
        },
        "commands": {k: " ".join(map(str, v)) for k, v in commands.items()},
        "in_process": {
            **inside,
            "read_campaign_seconds": _summary(reader),
            "loadtxt_seconds": _summary(ref),
            "reader_over_loadtxt": _summary(reader)["median"] / _summary(ref)["median"],
        },
        "targets": {
            "calibrate_over_loadtxt_wall": {
                "value": med["calibrate"] / med["loadtxt"],
                "max": CALIBRATE_OVER_LOADTXT_MAX,
            },
            "calibrate_over_fit_peak_rss": {
                "value": peak["calibrate"] / peak["fit_only"],
                "max": CALIBRATE_OVER_FIT_MEMORY_MAX,
            },
            "calibrate_over_fit_peak_tracemalloc": {
                "value": inside["calibrate_over_fit"],
                "max": CALIBRATE_OVER_FIT_MEMORY_MAX,
            },
            "reader_over_loadtxt": {
                "value": _summary(reader)["median"] / _summary(ref)["median"],
                "max": 1.0,
            },
        },
    }


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
    from robocal.solver.problem import Problem

    from ..formats.campaign_csv import read_campaign, write_campaign
    from .diagnose import timed_campaign

    cell, meas = timed_campaign(poses, seed)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "meas.csv"
        write_campaign(path, meas)
        numeric = _numeric_columns(cell.robot)
        ref, _ = _timed(
            lambda: np.loadtxt(path, delimiter=",", skiprows=1, usecols=numeric), repeats=3
        )
        read = read_campaign(path, cell.robot)
    problem = Problem.of(cell.robot, cell.target_positions(read.target_names), read)
    before = peak_rss_mib()
    t0, c0 = time.perf_counter(), time.process_time()
    diagnose(problem)
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
