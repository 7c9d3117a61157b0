"""`robocal diagnose` through the command line: the report, the extended model and the figures
are written where asked, the model evaluates and predicts from its file (visit order from
time_s, else file order). The numerics over many drawn effects are checked in process in
tests/solver/test_diagnose_effects.py; here a few of the same draws go through the files."""

import json

import numpy as np
import pytest

from robocal.server.formats.cell_json import Cell, cell_to_json
from tests import cli_process
from tests.solver.test_diagnose_effects import aim, cell_of, draw, draw_backlash, robot_for


def robocal(*args, cwd):
    r = cli_process.run(*args, cwd=cwd, timeout=600)
    assert r.returncode == 0, r.stderr
    return r


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("diagnose")
    paths = {}
    for name in ("irb2600", "kuka-like"):
        paths[name] = d / f"{name}.json"
        sim = cell_of(name)
        paths[name].write_text(json.dumps(cell_to_json(Cell(sim.robot, sim.targets))))
    return d, paths


def run(workdir, robot, seed, specs):
    d, paths = workdir
    stem = f"{robot}-{seed}"
    args = ["simulate", "--cell", paths[robot], "--poses", 100, "--seed", seed]
    args += ["--out", f"{stem}.csv", "--truth-out", f"{stem}-truth.json"]
    for s in specs:
        args += ["--effect", s]
    robocal(*args, cwd=d)
    r = robocal(
        "diagnose",
        f"{stem}.csv",
        "--cell",
        paths[robot],
        "--out",
        f"{stem}/report.json",
        "--model-out",
        f"{stem}/model.json",
        cwd=d,
    )
    report = json.loads((d / stem / "report.json").read_text())
    truth = json.loads((d / f"{stem}-truth.json").read_text())
    return report, truth, d / stem, r


@pytest.mark.parametrize("seed", [0, 3])  # a compliance on the IRB, a periodic error on the KUKA
def test_diagnose_writes_the_report_the_model_and_the_figure(workdir, seed):
    robot = robot_for(seed)
    spec, name, joint, harmonic, target = draw(seed)
    magnitude = aim(cell_of(robot), spec, name, seed, target)
    report, truth, out, r = run(workdir, robot, seed, [f"{spec}={magnitude:.6g}"])
    found = report["effects"][0]
    assert (found["name"], found.get("joint"), found.get("harmonic")) == (name, joint, harmonic)
    assert report["final"]["holdout_rmse_mm"] <= 1.3 * truth["noise_floor_mm"]
    assert (out / found["figure"]).stat().st_size > 10_000
    model = json.loads((out / "model.json").read_text())
    assert [e["name"] for e in model["extensions"]] == [name]
    assert name in r.stdout


def test_clean_campaign_reports_no_effect(workdir):
    report, truth, out, r = run(workdir, "irb2600", 200, [])
    assert report["effects"] == []
    assert "no effect beyond geometry pays off" in r.stdout
    assert report["noise_floor_mm"] == pytest.approx(truth["noise_floor_mm"], rel=0.25)
    assert not json.loads((out / "model.json").read_text()).get("extensions")


def test_extended_model_evaluates_with_time_and_temperature(workdir):
    d, _ = workdir
    report, truth, out, _ = run(workdir, "irb2600", 301, ["thermal_drift=30"])
    assert [e["name"] for e in report["effects"]] == ["thermal_drift"]
    model = json.loads((out / "model.json").read_text())
    assert model["extensions"][0]["name"] == "thermal_drift"
    r = robocal(
        "evaluate", out / "model.json", "irb2600-301.csv", "--json", out / "eval.json", cwd=d
    )
    ev = json.loads((out / "eval.json").read_text())
    assert ev["model"]["rmse"] <= 1.3 * truth["noise_floor_mm"]
    assert "improvement over nominal" in r.stdout


def read_predictions(path):
    rows = [line.split(",") for line in path.read_text().splitlines()[1:]]
    return {(r[0], r[1]): np.array([float(v) for v in r[2:5]]) for r in rows}


def write_poses(src, dst, order, keep_time):
    """A poses file from a meas.csv: its poses in `order`, with or without the time_s column."""
    lines = src.read_text().splitlines()
    head = lines[0].split(",")
    keep = [i for i, h in enumerate(head) if keep_time or h not in ("time_s", "temp_c")]
    by_pose = {}
    for line in lines[1:]:
        by_pose.setdefault(line.split(",")[0], []).append(line.split(","))
    ids = list(by_pose)
    out = [",".join(head[i] for i in keep)]
    out += [",".join(r[i] for i in keep) for k in order for r in by_pose[ids[k]]]
    dst.write_text("\n".join(out) + "\n")


def write_measured(src, dst):
    """The measured readings of a meas.csv in pred.csv's columns (pose, target, x, y, z)."""
    lines = src.read_text().splitlines()
    head = lines[0].split(",")
    cols = [head.index(c) for c in ("pose", "target", "x", "y", "z")]
    dst.write_text("\n".join(",".join(line.split(",")[i] for i in cols) for line in lines) + "\n")
    return dst


def test_backlash_model_predicts_from_its_file_in_visit_order(workdir):
    """predict takes the visit order from the poses file's time_s, else from its row order."""
    d, _ = workdir
    seed = 400
    robot = robot_for(seed)
    joint, target, rng = draw_backlash(seed)
    spec = f"joint_backlash:{joint}"
    magnitude = aim(cell_of(robot), spec, "joint_backlash", seed, target)
    report, truth, out, _ = run(workdir, robot, seed, [f"{spec}={magnitude:.6g}"])
    assert [(e["name"], e.get("joint")) for e in report["effects"]] == [("joint_backlash", joint)]
    floor = truth["noise_floor_mm"]
    meas = d / f"{robot}-{seed}.csv"
    shuffled = rng.permutation(100)
    write_poses(meas, out / "timed.csv", shuffled, keep_time=True)  # file order != visit order
    write_poses(meas, out / "untimed.csv", range(100), keep_time=False)  # file order = visit
    write_poses(meas, out / "wrong.csv", shuffled, keep_time=False)
    pred = {}
    for name in ("timed", "untimed", "wrong"):
        robocal(
            "predict",
            out / "model.json",
            out / f"{name}.csv",
            "--out",
            out / f"{name}-pred.csv",
            cwd=d,
        )
        pred[name] = read_predictions(out / f"{name}-pred.csv")
    truth_xyz = read_predictions(write_measured(meas, out / "measured.csv"))

    def rms(p):
        return np.sqrt(np.mean([np.sum((p[k] - v) ** 2) for k, v in truth_xyz.items()]))

    keys = sorted(pred["timed"])
    np.testing.assert_allclose(
        [pred["timed"][k] for k in keys], [pred["untimed"][k] for k in keys], atol=2e-6
    )
    assert rms(pred["timed"]) <= 1.3 * floor
    assert rms(pred["wrong"]) > 2.0 * floor
