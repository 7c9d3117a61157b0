"""`robocal bench startup` times numpy's import, `robocal --help` and a 10-pose predict in one
run and prints them with the margins to the targets (no timing asserted: the JSON's shape)."""

import json
import subprocess
import sys


def test_bench_startup_prints_the_three_times_and_the_margins(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "robocal.server.cli", "bench", "startup", "--repeats", "2"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    names = {"import_numpy", "help", "predict"}
    assert out["benchmark"] == "startup" and out["repeats"] == 2 and out["predict_poses"] == 10
    assert set(out["median_s"]) == names and set(out["runs_s"]) == names
    assert all(len(ts) == 2 and all(t > 0 for t in ts) for ts in out["runs_s"].values())
    assert (
        out["commands"]["predict"].startswith("robocal")
        and " predict " in out["commands"]["predict"]
    )
    med = out["median_s"]
    assert out["help_over_numpy_s"] == round(med["help"] - med["import_numpy"], 4)
    assert out["targets_s"] == {"help_over_numpy": 0.3, "predict": 1.0}
    margins = out["margins_s"]
    assert margins["predict"] == round(1.0 - med["predict"], 4)
    assert out["met"] == {
        "help_over_numpy": margins["help_over_numpy"] >= 0,
        "predict": margins["predict"] >= 0,
    }
    assert not list(tmp_path.iterdir())  # its files went to a temporary directory
