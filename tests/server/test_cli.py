"""The robocal command line end to end, and its refusals of bad input."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests import cli_process


def robocal(*args, cwd):
    """`robocal ARGS` in its own process (forked from one that has imported the program)."""
    return cli_process.run(*args, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    r = robocal(
        "simulate",
        "--poses",
        150,
        "--seed",
        4,
        "--out",
        "all.csv",
        "--truth-out",
        "truth.json",
        cwd=d,
    )
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(d / "all.csv")))
    head = list(rows[0])
    for name, keep in (("cal.csv", lambda p: p <= 100), ("hold.csv", lambda p: p > 100)):
        with open(d / name, "w", newline="") as f:
            w = csv.DictWriter(f, head)
            w.writeheader()
            w.writerows(r for r in rows if keep(int(r["pose"])))
    return d


def test_simulate_writes_the_spec_columns(workdir):
    header = open(workdir / "all.csv").readline().strip().split(",")
    assert header[:8] == ["pose", "q1", "q2", "q3", "q4", "q5", "q6", "target"]
    assert {"x", "y", "z", "time_s", "temp_c"} <= set(header)
    truth = json.loads((workdir / "truth.json").read_text())
    assert 0.005 < truth["noise_floor_mm"] < 0.05


def test_calibrate_predict_evaluate(workdir):
    r = robocal(
        "calibrate",
        "cal.csv",
        "--method",
        "minimax",
        "--out",
        "model.json",
        "--recording",
        "cal.rrd",
        cwd=workdir,
    )
    assert r.returncode == 0, r.stderr
    rerun = Path(sys.executable).parent / "rerun"
    v = subprocess.run(
        [str(rerun), "rrd", "verify", str(workdir / "cal.rrd")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert v.returncode == 0, v.stderr
    assert "held fixed: theta1" in r.stdout and "SQP" in r.stdout
    model = json.loads((workdir / "model.json").read_text())
    assert model["schema"] == 1 and model["method"] == "minimax"
    assert model["data"]["poses"] == 100 and len(model["data"]["sha256"]) == 64
    assert set(model["targets"]) == {"A", "B", "C"}
    assert any("beta" in j for j in model["robot"]["joints"])

    r = robocal("predict", "model.json", "hold.csv", "--out", "pred.csv", cwd=workdir)
    assert r.returncode == 0, r.stderr
    pred = {
        (p["pose"], p["target"]): np.array([float(p[c]) for c in "xyz"])
        for p in csv.DictReader(open(workdir / "pred.csv"))
    }
    meas = {
        (p["pose"], p["target"]): np.array([float(p[c]) for c in "xyz"])
        for p in csv.DictReader(open(workdir / "hold.csv"))
    }
    assert pred.keys() == meas.keys() and len(pred) == 150
    rms = np.sqrt(np.mean([np.sum((pred[k] - meas[k]) ** 2) for k in meas]))
    floor = json.loads((workdir / "truth.json").read_text())["noise_floor_mm"]
    assert rms < 1.2 * floor

    r = robocal("evaluate", "model.json", "hold.csv", "--json", "eval.json", cwd=workdir)
    assert r.returncode == 0, r.stderr
    assert "AO' (log)" in r.stdout and "improvement over nominal" in r.stdout
    ev = json.loads((workdir / "eval.json").read_text())
    # pred.csv holds 1e-6 mm: its RMS of ~0.015 mm differs from the model's by ~1e-8 mm
    assert ev["model"]["rmse"] == pytest.approx(rms, rel=1e-5)
    assert ev["improvement_pct"]["ap_mean"] > 90


def test_compare_prints_table3(workdir):
    r = robocal("compare", "cal.csv", "--json", "cmp.json", cwd=workdir)
    assert r.returncode == 0, r.stderr
    for label in (
        "nominal",
        "ls-single:A",
        "ls-single:C",
        "ls-sum",
        "minimax",
        "ls-pose",
        "RMSE(phi)",
        "AO' mean",
    ):
        assert label in r.stdout
    assert "smallest max F_i: minimax" in r.stdout
    cmp = json.loads((workdir / "cmp.json").read_text())
    worst = {k: max(v["F"].values()) for k, v in cmp.items()}
    assert worst["minimax"] <= min(worst.values()) * (1 + 1e-6)


def one_line_error(r, *fragments):
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


def test_malformed_campaign_is_refused_with_its_location(workdir):
    lines = open(workdir / "cal.csv").read().splitlines()
    cols = lines[0].split(",")
    row = lines[5].split(",")
    row[cols.index("q3")] = "twelve"
    lines[5] = ",".join(row)
    (workdir / "bad.csv").write_text("\n".join(lines) + "\n")
    one_line_error(
        robocal("calibrate", "bad.csv", "--out", "bad.json", cwd=workdir),
        f"bad.csv:6:{cols.index('q3') + 1}",
        "q3",
    )
    assert not (workdir / "bad.json").exists()


def test_joint_outside_limits_is_refused(workdir):
    lines = open(workdir / "cal.csv").read().splitlines()
    cols = lines[0].split(",")
    for i in (1, 2, 3):  # every row of the first pose, so the pose stays consistent
        row = lines[i].split(",")
        row[cols.index("q2")] = "170.0"
        lines[i] = ",".join(row)
    (workdir / "limits.csv").write_text("\n".join(lines) + "\n")
    one_line_error(robocal("calibrate", "limits.csv", cwd=workdir), "limits.csv:2:", "q2")


def test_malformed_cell_is_refused_with_line_and_column(workdir):
    (workdir / "cell.json").write_text(
        '{\n  "robot": {"name": "x", "convention": "dh",\n'
        '    "joints": [{"a": 0, "d": 400, "theta": 0, "alpha": "ninety"}]},\n'
        '  "targets": {"A": [0, 0, 50]}\n}\n'
    )
    msg = one_line_error(
        robocal("calibrate", "cal.csv", "--cell", "cell.json", cwd=workdir), "cell.json:3:", "alpha"
    )
    col = int(msg.split("cell.json:3:")[1].split(":")[0])
    assert '"ninety"' == open(workdir / "cell.json").read().splitlines()[2][col - 1 : col + 7]
    (workdir / "broken.json").write_text('{"robot": "irb2600",\n "targets": {"A": [0, 0,]}}\n')
    one_line_error(
        robocal("compare", "cal.csv", "--cell", "broken.json", cwd=workdir), "broken.json:2:"
    )


def test_bad_arguments_are_refused(workdir):
    one_line_error(robocal("calibrate", "nothere.csv", cwd=workdir), "nothere.csv")
    one_line_error(
        robocal("calibrate", "cal.csv", "--method", "ls-single:Z", cwd=workdir), "ls-single:Z"
    )
    one_line_error(robocal("calibrate", "cal.csv", "--method", "gauss", cwd=workdir), "gauss")


def test_unidentifiable_data_is_refused(workdir):
    lines = open(workdir / "cal.csv").read().splitlines()
    (workdir / "few.csv").write_text(
        "\n".join(lines[:7]) + "\n"
    )  # two poses: fewer equations than parameters
    one_line_error(robocal("calibrate", "few.csv", cwd=workdir), "poses")


def test_demo_runs_the_whole_job(tmp_path):
    r = robocal("demo", "--poses", 40, "--holdout", 20, "--out", "d", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "Table 3" in r.stdout and "held-out RMS: nominal" in r.stdout
    out = tmp_path / "d"
    for name in (
        "robocal.db",
        "model.json",
        "model-extended.json",
        "report.json",
        "calibration.rrd",
    ):
        assert (out / name).stat().st_size > 0, name
    report = json.loads((out / "report.json").read_text())
    assert report["effects"][0]["name"] == "joint_compliance" and report["effects"][0]["joint"] == 2
    from robocal.server.formats.report_doc import ReportDoc

    assert ReportDoc.model_validate(report).effects[0].joint == 2  # the report as published
    rerun = Path(sys.executable).parent / "rerun"
    v = subprocess.run(
        [str(rerun), "rrd", "verify", str(out / "calibration.rrd")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert v.returncode == 0, v.stderr
    # "after" is the final, extended model; the minimax calibration beside it as "geometric"
    printed = subprocess.run(
        [str(rerun), "rrd", "print", str(out / "calibration.rrd")],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    assert "/world/poses/held_out/error/geometric" in printed
    assert "/errors/per_pose/held_out/after" in printed
