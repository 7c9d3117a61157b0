"""Start-up benchmark: `robocal --help` and `robocal predict` on 10 poses, next to numpy's import."""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# The targets (issue 12, item 4): the command line's own import on top of numpy's, and a whole
# small prediction, on the machine the benchmark runs on.
HELP_OVER_NUMPY_MAX_S = 0.3
PREDICT_MAX_S = 1.0


def robocal_argv() -> list[str]:
    """The installed entry point beside this interpreter, else the module (a bare checkout)."""
    script = Path(sys.executable).parent / "robocal"
    if script.exists():
        return [str(script)]
    return [sys.executable, "-m", "robocal.server.cli"]


def _run(argv, cwd) -> None:
    r = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed: {r.stderr.strip()[-1000:]}")


def _wall(argv, cwd) -> float:
    t = time.perf_counter()
    _run(argv, cwd)
    return time.perf_counter() - t


def prepare_files(work: Path, poses: int) -> tuple[Path, Path]:
    """A model calibrated on a simulated campaign, and another campaign of `poses` poses to
    predict (a meas.csv is a valid poses file); made with the command line itself."""
    cli = robocal_argv()
    _run([*cli, "simulate", "--poses", "30", "--seed", "1", "--out", "cal.csv"], work)
    _run([*cli, "calibrate", "cal.csv", "--method", "ls-sum", "--out", "model.json"], work)
    _run([*cli, "simulate", "--poses", str(poses), "--seed", "2", "--out", "poses.csv"], work)
    return work / "model.json", work / "poses.csv"


def run_startup_bench(repeats: int = 7, poses: int = 10) -> dict:
    """Median wall times (fresh processes, interleaved so a busy spell hits all three alike) and
    the margins to the targets; a positive margin means the target is met."""
    cli = robocal_argv()
    with tempfile.TemporaryDirectory(prefix="robocal-bench-startup-") as tmp:
        work = Path(tmp)
        model, pose_file = prepare_files(work, poses)
        commands = {
            "import_numpy": [sys.executable, "-c", "import numpy"],
            "help": [*cli, "--help"],
            "predict": [*cli, "predict", model.name, pose_file.name, "--out", "pred.csv"],
        }
        for argv in commands.values():  # warm the file cache; not timed
            _run(argv, work)
        runs: dict[str, list[float]] = {name: [] for name in commands}
        for _ in range(repeats):
            for name, argv in commands.items():
                runs[name].append(_wall(argv, work))
    median = {name: round(statistics.median(ts), 4) for name, ts in runs.items()}
    help_over = round(median["help"] - median["import_numpy"], 4)
    return {
        "benchmark": "startup",
        "repeats": repeats,
        "predict_poses": poses,
        "cpus": os.cpu_count(),
        "commands": {
            name: " ".join(Path(a).name if i == 0 else a for i, a in enumerate(argv))
            for name, argv in commands.items()
        },
        "median_s": median,
        "runs_s": {name: [round(t, 4) for t in ts] for name, ts in runs.items()},
        "help_over_numpy_s": help_over,
        "predict_over_numpy_s": round(median["predict"] - median["import_numpy"], 4),
        "targets_s": {"help_over_numpy": HELP_OVER_NUMPY_MAX_S, "predict": PREDICT_MAX_S},
        "margins_s": {
            "help_over_numpy": round(HELP_OVER_NUMPY_MAX_S - help_over, 4),
            "predict": round(PREDICT_MAX_S - median["predict"], 4),
        },
        "met": {
            "help_over_numpy": help_over <= HELP_OVER_NUMPY_MAX_S,
            "predict": median["predict"] <= PREDICT_MAX_S,
        },
    }
