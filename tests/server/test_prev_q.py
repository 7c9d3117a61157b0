"""`prev_q1..prev_qN`: the joints the arm came from before a pose decide the backlash's approach
direction over the file's order, so a campaign shuffled and split into files diagnoses, predicts
and evaluates as in visit order; without them the shuffle changes the answers."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.server.calibration import workflow
from robocal.server.formats.campaign_csv import read_campaign, read_poses, write_campaign
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.errors import InputError
from robocal.server.formats.model_json import write_model
from robocal.solver.effects import Inputs
from tests.server.test_cli import robocal

SEED, POSES, BACKLASH = 4, 80, "joint_backlash:2=0.05"


@pytest.fixture(scope="module")
def campaign():
    """A campaign with backlash on joint 2, untimed (the file order is then the visit order), each
    pose with the joints the arm came from; the first pose, mid-play, left out."""
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=SEED)
    vc.effects.extend(make_effects([BACKLASH], vc, SEED))
    meas = vc.campaign(POSES, seed=SEED)
    prev = np.vstack([np.full((1, meas.q.shape[1]), np.nan), meas.q[:-1]])
    meas = replace(meas, time_s=None, prev_q=prev).subset(np.arange(1, POSES))
    shuffled = np.random.default_rng(0).permutation(meas.n_poses)
    return cell, meas, shuffled


def backlash(model):
    return [np.degrees(e.coef[0]) for e in model.extensions if e.name == "joint_backlash"]


def test_the_diagnosis_of_a_shuffled_campaign_is_the_visit_orders(campaign):
    cell, meas, shuffled = campaign
    _, ordered = workflow.diagnose(cell, meas, screen=False)
    _, with_prev = workflow.diagnose(cell, meas.subset(shuffled), screen=False)
    _, without = workflow.diagnose(cell, replace(meas.subset(shuffled), prev_q=None), screen=False)
    assert [e.label() for e in with_prev.extensions] == [e.label() for e in ordered.extensions]
    assert backlash(ordered) == pytest.approx([-0.05], rel=0.02)
    assert backlash(with_prev) == pytest.approx(backlash(ordered), rel=1e-6)
    # without the joints it came from, the shuffled file's order says nothing of the approach
    assert not backlash(without) or abs(backlash(without)[0]) < 0.025


def test_prev_q_takes_precedence_over_the_visit_order(campaign):
    _, meas, shuffled = campaign
    # the file order is the visit order; its first pose's approach it cannot know
    in_order = Inputs(meas.q).motion
    assert not in_order[0].any()
    in_order[0] = np.sign(meas.q[0] - meas.prev_q[0])
    assert np.array_equal(Inputs(meas.q, prev_q=meas.prev_q).motion, in_order)
    sub = meas.subset(shuffled)
    assert np.array_equal(Inputs(sub.q, prev_q=sub.prev_q).motion, in_order[shuffled])
    assert np.mean(Inputs(sub.q).motion != in_order[shuffled]) > 0.2


def test_split_files_predict_and_evaluate_as_the_whole_in_visit_order(campaign, tmp_path):
    """The shuffled campaign written as two files, with and without prev_q columns: `robocal
    predict` on each half gives the in-order campaign's predictions only with them; `evaluate`
    likewise."""
    cell, meas, shuffled = campaign
    _, model = workflow.diagnose(cell, meas, screen=False)
    write_model(tmp_path / "model.json", model)
    want = workflow.model_predict(model, meas.q, prev_q=meas.prev_q)
    halves = np.array_split(shuffled, 2)
    got = {True: np.zeros_like(want), False: np.zeros_like(want)}
    for keep in (True, False):
        for h, idx in enumerate(halves):
            part = meas.subset(idx)
            name = f"half{h}{'p' if keep else ''}.csv"
            write_campaign(tmp_path / name, part if keep else replace(part, prev_q=None))
            r = robocal("predict", "model.json", name, "--out", f"pred_{name}", cwd=tmp_path)
            assert r.returncode == 0, r.stderr
            rows = np.loadtxt(
                tmp_path / f"pred_{name}", delimiter=",", skiprows=1, usecols=(2, 3, 4)
            )
            got[keep][idx] = rows.reshape(len(idx), -1, 3)
    np.testing.assert_allclose(got[True], want, atol=2e-6)  # as printed, 1e-6 mm
    off = np.linalg.norm(got[False] - want, axis=-1).max(axis=1)
    assert np.mean(off > 0.1) > 0.2  # the approach guessed wrong at many poses: 0.1 mm and more
    rmse = {
        name: workflow.evaluate(model, read_campaign(tmp_path / name, cell.robot)).model.rmse
        for name in ("half0p.csv", "half0.csv")
    }
    assert rmse["half0p.csv"] < 0.03 < 0.1 < rmse["half0.csv"], rmse


def _lines(tmp_path, meas, change):
    write_campaign(tmp_path / "meas.csv", meas)
    lines = (tmp_path / "meas.csv").read_text().splitlines()
    cells = [ln.split(",") for ln in lines]
    change(cells)
    (tmp_path / "meas.csv").write_text("\n".join(",".join(c) for c in cells) + "\n")
    return tmp_path / "meas.csv"


@pytest.mark.parametrize(
    "change,where",
    [
        # header: pose, q1..q6, target, x, y, z, prev_q1..prev_q6 (columns 11 to 16)
        (lambda c: [r.pop() for r in c], "meas.csv:1: missing column 'prev_q6'"),
        (lambda c: c[2].__setitem__(13, ""), "meas.csv:3:14: column 'prev_q3': empty field"),
        (lambda c: c[2].__setitem__(11, "abc"), "meas.csv:3:12: column 'prev_q1': 'abc' is not"),
        (
            lambda c: c[3].__setitem__(12, "170"),
            "meas.csv:4:13: column 'prev_q2': 170 deg is outside",
        ),
        (
            lambda c: c[2].__setitem__(11, str(float(c[2][11]) + 1)),
            "meas.csv:3:12: column 'prev_q1': the joints the arm came from differ from line 2",
        ),
    ],
)
def test_bad_prev_q_is_refused_naming_file_line_and_field(campaign, tmp_path, change, where):
    cell, meas, _ = campaign
    path = _lines(tmp_path, replace(meas.subset(np.arange(3)), temp_c=None), change)
    for read in (read_campaign, read_poses):
        with pytest.raises(InputError) as e:
            read(path, cell.robot)
        assert str(e.value).startswith(str(tmp_path / where)), str(e.value)


def test_prev_q_round_trips_and_a_pose_may_lack_it(campaign, tmp_path):
    cell, meas, _ = campaign
    part = meas.subset(np.arange(4))
    prev = part.prev_q.copy()
    prev[2] = np.nan  # a pose without the joints it came from: blank fields
    write_campaign(tmp_path / "m.csv", replace(part, prev_q=prev))
    back = read_campaign(tmp_path / "m.csv", cell.robot)
    np.testing.assert_allclose(back.prev_q, prev, atol=1e-9)
    assert np.isnan(back.prev_q[2]).all()
    np.testing.assert_allclose(read_poses(tmp_path / "m.csv", cell.robot)[4], prev, atol=1e-9)


def test_targets_read_prev_q_for_compensation(campaign, tmp_path):
    from robocal.server.formats.targets_csv import read_targets

    cell, meas, _ = campaign
    part = replace(meas.subset(np.arange(3)), temp_c=None)
    write_campaign(tmp_path / "t.csv", part)  # a meas.csv has a targets.csv's columns
    t = read_targets(tmp_path / "t.csv", cell.robot, part.target_names)
    np.testing.assert_allclose(t.prev_q, part.prev_q, atol=1e-9)
    text = (tmp_path / "t.csv").read_text().splitlines()
    (tmp_path / "u.csv").write_text("\n".join(ln.rsplit(",", 1)[0] for ln in text) + "\n")
    with pytest.raises(InputError, match=r"u.csv:1: missing column 'prev_q6'"):
        read_targets(tmp_path / "u.csv", cell.robot, part.target_names)


def _with_prev(tmp_path, meas, prev_rad, name="m.csv"):
    """The campaign written with prev_q1..prev_qN fields holding prev_rad's numbers as read
    (write_campaign prints degrees: radians are written by passing them as degrees)."""
    write_campaign(tmp_path / name, replace(meas, prev_q=prev_rad))
    return tmp_path / name


def test_prev_q_in_radians_is_refused_naming_line_field_and_unit(campaign, tmp_path):
    """prev_q1..prev_qN given in radians beside q1..qN in degrees (or the other way round) would
    turn every backlash's approach toward zero: each reader refuses them in one line, and `robocal
    predict` and `evaluate` exit non-zero with that line."""
    from robocal.server.formats.targets_csv import read_targets

    cell, meas, _ = campaign
    part = replace(meas.subset(np.arange(20)), temp_c=None)
    path = _with_prev(tmp_path, part, np.deg2rad(part.prev_q))  # the fields: radians
    for read in (read_campaign, read_poses, lambda p, r: read_targets(p, r, part.target_names)):
        with pytest.raises(InputError) as e:
            read(path, cell.robot)
        msg = str(e.value)
        assert msg.startswith(f"{path}:") and "column 'prev_q" in msg, msg
        assert "prev_q1..prev_q6 look like radians" in msg, msg
        assert msg.endswith("give them in degrees") and "\n" not in msg
    _, model = workflow.diagnose(cell, replace(meas, time_s=None), screen=False)
    write_model(tmp_path / "model.json", model)
    for args in (
        ("predict", "model.json", "m.csv", "--out", "p.csv"),
        ("evaluate", "model.json", "m.csv"),
    ):
        r = robocal(*args, cwd=tmp_path)
        assert r.returncode != 0 and "Traceback" not in r.stderr
        assert r.stderr.count("\n") == 1 and "look like radians" in r.stderr, r.stderr
    assert not (tmp_path / "p.csv").exists()
    # joints in radians beside prev_q in degrees: the joints are named
    q_rad = _with_prev(tmp_path, replace(part, q=np.deg2rad(part.q)), part.prev_q, "q.csv")
    with pytest.raises(InputError, match=r"column 'q\d+': .* q1..q6 look like radians"):
        read_poses(q_rad, cell.robot)


@pytest.mark.parametrize("poses", [3, 5, 20])
def test_prev_q_in_degrees_is_never_taken_for_radians(campaign, tmp_path, poses):
    """The joints an arm comes from, in degrees, pass: the previous pose's (any run of poses),
    home at zero joints for the first pose or for all of them, or an approach point beside each
    pose; a pose from home alone never refuses the file."""
    cell, meas, _ = campaign
    n = meas.q.shape[1]
    for start in range(0, meas.n_poses - poses, poses):
        part = meas.subset(np.arange(start, start + poses))
        homes = np.zeros_like(part.prev_q)
        first_home = part.prev_q.copy()
        first_home[0] = 0.0
        beside = part.q - np.deg2rad(2.0)
        beside = np.clip(beside, cell.robot.lower, cell.robot.upper)
        for prev in (part.prev_q, homes, first_home, beside, np.radians(np.full((poses, n), 1e-3))):
            path = _with_prev(tmp_path, part, prev)
            read_campaign(path, cell.robot)  # no InputError


def test_files_with_other_columns_pasted_together_name_the_second_header(campaign, tmp_path):
    """Two halves of a campaign pasted together, the second written with prev_q columns: `robocal
    calibrate` names the second header line and the columns it adds, not "row has 17 fields";
    nothing is written."""
    cell, meas, _ = campaign
    write_campaign(tmp_path / "a.csv", replace(meas.subset(np.arange(10)), prev_q=None))
    write_campaign(tmp_path / "b.csv", meas.subset(np.arange(10, 20)))
    a = (tmp_path / "a.csv").read_text()
    (tmp_path / "ab.csv").write_text(a + (tmp_path / "b.csv").read_text())
    second = len(a.splitlines()) + 1
    r = robocal("calibrate", "ab.csv", "--out", "model.json", cwd=tmp_path)
    assert r.returncode != 0 and r.stderr.count("\n") == 1, r.stderr
    assert f"ab.csv:{second}: line {second} is a second header row" in r.stderr, r.stderr
    assert "other columns (adds 'prev_q1', 'prev_q2', 'prev_q3' and 3 more)" in r.stderr
    assert not (tmp_path / "model.json").exists()
