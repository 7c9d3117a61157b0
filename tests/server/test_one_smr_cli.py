"""One SMR on the flange axis end to end: calibrate (every method) and diagnose hold the last
joint's offset instead of refusing, and the noise floor comes from the tracker's specification."""

import json

import pytest

from robocal.server.formats.cell_json import robot_to_json
from tests.robots import IIWA_LIKE, PUMA_LIKE, UR5
from tests.server.test_cli import robocal

CELLS = {
    "irb2600": ("irb2600", 6, None),
    "ur5": (robot_to_json(UR5), 6, None),  # inline robots: DH, a 7-axis arm, modified DH
    "iiwa": (robot_to_json(IIWA_LIKE), 7, {"mpe_um": 15.0, "mpe_um_per_m": 6.0}),
    "puma-mdh": (robot_to_json(PUMA_LIKE), 6, None),
}


@pytest.mark.parametrize("name", list(CELLS))
def test_one_smr_on_the_axis_calibrates_and_diagnoses(name, tmp_path):
    robot, n, tracker = CELLS[name]
    cell = {"robot": robot, "targets": {"A": [0.0, 0.0, 40.0]}}
    if tracker:
        cell["tracker"] = tracker
    (tmp_path / "cell.json").write_text(json.dumps(cell))
    r = robocal(
        "simulate",
        "--cell",
        "cell.json",
        "--poses",
        40,
        "--seed",
        5,
        "--out",
        "m.csv",
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    for method in ("minimax", "ls-sum", "ls-single:A"):
        r = robocal("calibrate", "m.csv", "--cell", "cell.json", "--method", method, cwd=tmp_path)
        assert r.returncode == 0, (method, r.stderr)
        fixed = json.loads((tmp_path / "model.json").read_text())["fit"]["fixed_parameters"]
        assert f"theta{n}" in fixed and f"d{n}" in fixed, (method, fixed)
        assert f"theta{n} (" in " ".join(r.stdout.split())  # the summary says it is held, and why
    r = robocal("diagnose", "m.csv", "--cell", "cell.json", "--out", "report.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    model = json.loads((tmp_path / "model.json").read_text())
    assert f"theta{n}" in {f["parameter"] for f in model["identified"]["fixed"]}
    floor, source = report["noise_floor_mm"], report["noise_floor_source"]
    assert 0.005 < floor < 0.05
    if tracker:
        assert source.startswith("tracker specification (MPE 15 um + 6 um/m")
    else:
        assert source.startswith("tracker specification (default MPE 10 um + 2.5 um/m")
    # the summary prints the report's floor and its source, and the model's validation agrees
    out = " ".join(r.stdout.split())  # unwrapped
    assert f"noise floor {floor:.4f} mm (from the tracker specification (" in out
    assert model["validation"]["noise_floor_mm"] == pytest.approx(floor)
    assert model["validation"]["noise_floor_source"] == source


def test_one_smr_error_above_the_spec_floor_is_reported_unexplained(tmp_path):
    """An unmodelled wrist coupling with one SMR: the `unexplained` block is judged against the
    tracker spec's floor (there was none with one SMR)."""
    cell = {"robot": "irb2600", "targets": {"A": [60.0, 0.0, 35.0]}}
    (tmp_path / "cell.json").write_text(json.dumps(cell))
    r = robocal(
        "simulate",
        *("--cell", "cell.json", "--poses", 40, "--seed", 4, "--out", "m.csv"),
        *("--effect", "joint_coupling:5=300"),
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    r = robocal("diagnose", "m.csv", "--cell", "cell.json", "--out", "report.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    floor = report["noise_floor_mm"]
    assert report["final"]["holdout_rmse_mm"] > 1.5 * floor
    ratio = report["unexplained"]["noise_floor_ratio"]
    assert ratio == pytest.approx(report["unexplained"]["holdout_rmse_mm"] / floor)
    assert f"{ratio:.1f}x the noise floor" in " ".join(r.stdout.split())
