"""File formats: campaign CSV, poses/predictions CSV and cell JSON, read from real files."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from robocal.server.formats import (
    Cell,
    InputError,
    cell_to_json,
    default_cell,
    parse_cell,
    read_campaign,
    read_cell,
    read_poses,
    robot_from_json,
    robot_to_json,
    write_campaign,
    write_predictions,
)
from robocal.solver.measurements import Measurements
from robocal.solver.robot import IRB2600, robot_from_degrees

HEAD = "pose,q1,q2,q3,q4,q5,q6,target,x,y,z"


def put(tmp_path, name, text, encoding="utf-8"):
    path = tmp_path / name
    path.write_text(text, encoding=encoding)
    return path


def refused(call, path, line, column=None) -> str:
    """The message of the InputError raised by call(), checking its path:line[:column] prefix."""
    with pytest.raises(InputError) as info:
        call()
    err = info.value
    where = f"{path}:{line}:" if column is None else f"{path}:{line}:{column}:"
    text = str(err)
    assert text.startswith(where), text
    assert "\n" not in text
    assert (err.line, err.column) == (line, column)
    return text


# -- campaign CSV ---------------------------------------------------------------------------


def campaign() -> Measurements:
    rng = np.random.default_rng(1)
    m, names = 4, ("A", "B", "C")
    q = np.deg2rad(rng.uniform(-60, 60, (m, 6)))
    xyz = rng.uniform(-1500, 1500, (m, 3, 3))
    xyz[1, 2] = np.nan  # beam break
    xyz[3, 0] = np.nan
    time_s = np.arange(m * 3, dtype=float).reshape(m, 3) * 1.25
    temp_c = 20.0 + 0.01 * time_s
    time_s[~np.all(np.isfinite(xyz), axis=-1)] = np.nan
    temp_c[~np.all(np.isfinite(xyz), axis=-1)] = np.nan
    temp_c[2, 1] = np.nan  # weather station missed one reading
    return Measurements(["p1", "p2", "7", "x 4"], q, names, xyz, time_s, temp_c)


def test_campaign_round_trip(tmp_path):
    meas = campaign()
    path = tmp_path / "meas.csv"
    write_campaign(path, meas)
    back = read_campaign(path, IRB2600)
    assert back.pose_ids == meas.pose_ids
    assert back.target_names == meas.target_names
    np.testing.assert_allclose(back.q, meas.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(back.xyz, meas.xyz, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(back.mask, meas.mask)
    np.testing.assert_allclose(back.time_s, meas.time_s, atol=1e-6)
    np.testing.assert_allclose(back.temp_c, meas.temp_c, atol=1e-6)
    assert back.n_readings == 10
    assert len(path.read_text().splitlines()) == 1 + 10
    assert os.listdir(tmp_path) == ["meas.csv"]


def test_campaign_without_extras_round_trips(tmp_path):
    meas = campaign()
    meas.time_s = meas.temp_c = None
    write_campaign(tmp_path / "m.csv", meas)
    assert (tmp_path / "m.csv").read_text().splitlines()[0] == HEAD
    back = read_campaign(tmp_path / "m.csv", IRB2600)
    assert back.time_s is None and back.temp_c is None


def test_campaign_order_bom_whitespace_and_extra_columns(tmp_path):
    text = (
        "\ufeff target , note, z,y,x, pose ,q6,q5,q4,q3,q2,q1, TIME_S\n"
        "C, first ,3,2,1, 10 ,0,0,0,0,0,0, 0.5\n"
        "A,,6,5,4,10,0,0,0,0,0,0,1.5\n"
        "B,,9,8,7,2,60,50,40,30,20,10,2.5\n"
        "\n"
    )
    meas = read_campaign(put(tmp_path, "m.csv", text), IRB2600)
    assert meas.pose_ids == ["10", "2"]  # first appearance
    assert meas.target_names == ("A", "B", "C")  # sorted
    np.testing.assert_allclose(meas.q[1], np.deg2rad([10, 20, 30, 40, 50, 60]))
    np.testing.assert_array_equal(meas.xyz[0, 2], [1, 2, 3])
    np.testing.assert_array_equal(meas.xyz[0, 0], [4, 5, 6])
    assert meas.mask.tolist() == [[True, False, True], [False, True, False]]
    assert meas.time_s[1, 1] == 2.5 and meas.temp_c is None


def test_joint_exactly_at_limit_is_accepted(tmp_path):
    text = f"{HEAD}\n1,180,155,-180,400,-120,-400,A,0,0,0\n"
    meas = read_campaign(put(tmp_path, "m.csv", text), IRB2600)
    assert np.all(IRB2600.within_limits(meas.q + [0, -1e-9, 1e-9, -1e-9, 1e-9, 1e-9]))


ROW = "1,0,0,0,0,0,0,A,1,2,3"
# (name, file text, line, column, words the message must contain, bad text on that line)
CSV_REFUSALS = [
    ("empty", "", 1, None, ["empty"], None),
    ("blank", "\n\n", 1, None, ["empty"], None),
    (
        "missing column",
        "pose,q1,q2,q4,q5,q6,target,x,y,z\n" + "1,0,0,0,0,0,A,1,2,3\n",
        1,
        None,
        ["missing required column 'q3'"],
        None,
    ),
    ("semicolons", HEAD.replace(",", ";") + "\n", 1, None, ["'pose'", "semicolons"], None),
    (
        "short row",
        f"{HEAD}\n{ROW}\n1,0,0,0,0,0,0,B,1,2\n",
        3,
        11,
        ["column 'z'", "10 fields"],
        None,
    ),
    ("long row", f"{HEAD}\n{ROW},9\n", 2, 12, ["12 fields", "'9'"], None),
    (
        "not a number",
        f'{HEAD}\n{ROW}\n2,1,"12,5",3,4,5,6,A,1,2,3\n',
        3,
        3,
        ["column 'q2'", "'12,5' is not a number"],
        "12,5",
    ),
    (
        "nan",
        f"{HEAD}\n{ROW}\n2,0,0,0,0,0,0,A,NaN,2,3\n",
        3,
        9,
        ["column 'x'", "not a finite"],
        "NaN",
    ),
    ("inf", f"{HEAD}\n1,0,0,0,0,0,0,A,1,-inf,3\n", 2, 10, ["column 'y'", "not a finite"], "-inf"),
    ("overflow", f"{HEAD}\n1,0,0,0,0,0,0,A,1,2,1e999\n", 2, 11, ["column 'z'"], "1e999"),
    ("empty value", f"{HEAD}\n1,0,0,,0,0,0,A,1,2,3\n", 2, 4, ["column 'q3'", "empty"], None),
    (
        "empty pose",
        f"{HEAD}\n{ROW}\n  ,0,0,0,0,0,0,B,1,2,3\n",
        3,
        1,
        ["column 'pose'", "empty"],
        None,
    ),
    ("empty target", f"{HEAD}\n1,0,0,0,0,0,0,,1,2,3\n", 2, 8, ["column 'target'", "empty"], None),
    (
        "duplicate",
        f"{HEAD}\n{ROW}\n1,0,0,0,0,0,0,B,1,2,3\n1,0,0,0,0,0,0,A,1,2,3\n",
        4,
        8,
        ["column 'target'", "'A'", "pose '1'", "line 2"],
        None,
    ),
    (
        "outside limits",
        f"{HEAD}\n{ROW}\n2,0,160,0,0,0,0,A,1,2,3\n",
        3,
        3,
        ["column 'q2'", "160", "[-95, 155]"],
        "160",
    ),
    (
        "pose disagrees",
        f"{HEAD}\n{ROW}\n1,0,0,0,0.001,0,0,B,1,2,3\n",
        3,
        5,
        ["column 'q4'", "0.001", "line 2", "pose '1'"],
        "0.001",
    ),
    ("no data", f"{HEAD}\n\n", 1, None, ["no data rows"], None),
    ("duplicate header", f"{HEAD},x\n{ROW},1\n", 1, 12, ["'x' appears twice"], None),
    (
        "two files concatenated",
        f"{HEAD}\n{ROW}\n{HEAD}\n2,0,0,0,0,0,0,A,1,2,3\n",
        3,
        None,
        ["line 3 is a second header row", "line 1"],
        None,
    ),
    (
        "second file adds a column",
        f"{HEAD}\n{ROW}\n{HEAD},temp_c\n2,0,0,0,0,0,0,A,1,2,3,20.5\n",
        3,
        None,
        ["line 3 is a second header row", "other columns (adds 'temp_c')", "concatenated"],
        None,
    ),
    (
        "second file lacks columns",
        f"{HEAD},prev_q1,prev_q2,prev_q3,prev_q4,prev_q5,prev_q6\n{ROW},0,0,0,0,0,0\n{HEAD}\n",
        3,
        None,
        ["line 3 is a second header row", "(lacks 'prev_q1', 'prev_q2', 'prev_q3' and 3 more)"],
        None,
    ),
    (
        "second header, other first column and no pose",
        f"{HEAD}\n{ROW}\nid,{HEAD.removeprefix('pose,')}\n",
        3,
        None,
        ["line 3 is a second header row", "adds 'id', lacks 'pose'"],
        None,
    ),
    (
        "second header, columns reordered",
        f"{HEAD}\n{ROW}\n{HEAD.replace('x,y,z', 'z,y,x').upper()}\n",
        3,
        None,
        ["line 3 is a second header row"],
        None,
    ),
]


@pytest.mark.parametrize(
    "name,text,line,column,words,bad", CSV_REFUSALS, ids=[c[0] for c in CSV_REFUSALS]
)
def test_campaign_refusals(tmp_path, name, text, line, column, words, bad):
    path = put(tmp_path, "meas.csv", text)
    msg = refused(lambda: read_campaign(path, IRB2600), path, line, column)
    for w in words:
        assert w in msg
    if bad is not None:
        assert bad in text.splitlines()[line - 1]


def test_target_not_in_the_cell_is_named_at_its_line(tmp_path):
    """A lowercase 'a' where the cell has 'A' was refused with the file alone: now its line, its
    field, and that names are case-sensitive; a name unlike any gets no such hint."""
    path = put(tmp_path, "meas.csv", f"{HEAD}\n{ROW}\n1,0,0,0,0,0,0,b,1,2,3\n")
    msg = refused(lambda: read_campaign(path, IRB2600, ["A", "B", "C"]), path, 3, 8)
    assert "column 'target'" in msg and "'b'" in msg and "case-sensitive: 'B'" in msg
    path = put(tmp_path, "meas.csv", f"{HEAD}\n{ROW}\n1,0,0,0,0,0,0,D,1,2,3\n")
    msg = refused(lambda: read_campaign(path, IRB2600, ["A", "B", "C"]), path, 3, 8)
    assert "target 'D' is not among the cell's targets (A, B, C)" in msg and "case" not in msg
    assert read_campaign(path, IRB2600).target_names == ("A", "D")


def test_pose_disagreement_within_print_rounding_is_accepted(tmp_path):
    text = f"{HEAD}\n{ROW}\n1,0,0,0,0.0000001,0,0,B,1,2,3\n"
    meas = read_campaign(put(tmp_path, "m.csv", text), IRB2600)
    assert meas.q[0, 3] == 0.0  # the first row of the pose wins


def test_not_utf8_and_missing_file(tmp_path):
    path = tmp_path / "m.csv"
    path.write_bytes(f"{HEAD}\n1,0,0,0,0,0,0,\xc5,1,2,3\n".encode("latin-1"))
    assert "UTF-8" in refused(lambda: read_campaign(path, IRB2600), path, 2)
    missing = tmp_path / "nope.csv"
    with pytest.raises(InputError, match="cannot read"):
        read_campaign(missing, IRB2600)


def test_robot_with_fewer_joints_needs_fewer_columns(tmp_path):
    robot = robot_from_degrees(
        "planar", "dh", [(300, 0, 0, 0, (-170, 170)), (200, 0, 0, 0, (-170, 170))]
    )
    text = "pose,q1,q2,target,x,y,z\n1,10,-20,A,1,2,3\n"
    meas = read_campaign(put(tmp_path, "m.csv", text), robot)
    assert meas.q.shape == (1, 2)


def test_atomic_write_leaves_old_file_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "meas.csv"
    path.write_text("old content\n")

    def crash(src, dst):
        raise OSError("disk on fire")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError):
        write_campaign(path, campaign())
    assert path.read_text() == "old content\n"
    assert os.listdir(tmp_path) == ["meas.csv"]


# -- poses.csv and pred.csv -----------------------------------------------------------------


def test_read_poses_csv(tmp_path):
    text = (
        "pose,q1,q2,q3,q4,q5,q6,time_s,temp_c\n"
        "a,0,0,0,0,0,0,0,20.5\n"
        "b,10,20,30,40,50,60,12.5,20.6\n"
    )
    ids, q, time_s, temp_c, _ = read_poses(put(tmp_path, "poses.csv", text), IRB2600)
    assert ids == ["a", "b"]
    np.testing.assert_allclose(q[1], np.deg2rad([10, 20, 30, 40, 50, 60]))
    np.testing.assert_array_equal(time_s, [0, 12.5])
    np.testing.assert_array_equal(temp_c, [20.5, 20.6])


def test_read_poses_accepts_meas_csv(tmp_path):
    text = (
        f"{HEAD},time_s\n"
        "1,0,0,0,0,0,0,A,1,2,3,0.0\n"
        "1,0,0,0,0,0,0,B,not measured,,,0.5\n"
        "2,10,20,30,40,50,60,B,1,2,3,1.0\n"
    )
    ids, q, time_s, temp_c, _ = read_poses(put(tmp_path, "meas.csv", text), IRB2600)
    assert ids == ["1", "2"]
    assert q.shape == (2, 6)
    np.testing.assert_array_equal(time_s, [0.0, 1.0])  # first row of each pose
    assert temp_c is None


def test_read_poses_refusals(tmp_path):
    head = "pose,q1,q2,q3,q4,q5,q6"
    path = put(tmp_path, "poses.csv", f"{head}\na,0,0,0,0,0,0\na,0,0,0,0,0,0\n")
    assert "line 2" in refused(lambda: read_poses(path, IRB2600), path, 3, 1)
    path = put(tmp_path, "poses.csv", f"{head}\na,0,0,0,0,130,0\n")
    assert "column 'q5'" in refused(lambda: read_poses(path, IRB2600), path, 2, 6)
    path = put(tmp_path, "poses.csv", "pose,q1,q2,q3,q4,q5\na,0,0,0,0,0\n")
    assert "'q6'" in refused(lambda: read_poses(path, IRB2600), path, 1)


def test_write_predictions(tmp_path):
    path = tmp_path / "pred.csv"
    xyz = np.arange(12, dtype=float).reshape(2, 2, 3) + 0.5
    write_predictions(path, ["p1", "p2"], ("A", "B"), xyz)
    lines = path.read_text().splitlines()
    assert lines[0] == "pose,target,x,y,z"
    assert lines[1] == "p1,A,0.500000,1.500000,2.500000"
    assert lines[4].startswith("p2,B,9.5")
    with pytest.raises(ValueError):
        write_predictions(path, ["p1"], ("A", "B"), xyz)


# -- cell JSON ------------------------------------------------------------------------------

SPEC_CELL = """{
  "robot": "irb2600",
  "targets": {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]}
}"""

INLINE_DH = """{
  "robot": {"name": "my-arm", "convention": "dh",
   "joints": [
    {"a": 150, "d": 445, "theta": 0, "alpha": -90, "limits": [-180, 180]},
    {"a": 900, "d": 0, "theta": -90, "alpha": 0, "limits": [-95, 155]},
    {"a": 150, "d": 0, "theta": 0, "alpha": -90, "limits": [-180, 75]},
    {"a": 0, "d": 938, "theta": 0, "alpha": 90, "limits": [-400, 400]},
    {"a": 0, "d": 0, "theta": 180, "alpha": 90, "limits": [-120, 120]},
    {"a": 0, "d": 200, "theta": 0, "alpha": 0, "limits": [-400, 400]}
   ]},
  "targets": {"A": [60.0, 0.0, 35.0]}
}"""

# The same arm in Craig's modified convention (each joint's twist and length move to the next).
INLINE_MDH = """{
  "robot": {"name": "my-arm-mdh", "convention": "mdh",
   "joints": [
    {"a": 0, "d": 445, "theta": 0, "alpha": 0},
    {"a": 150, "d": 0, "theta": -90, "alpha": -90},
    {"a": 900, "d": 0, "theta": 0, "alpha": 0},
    {"a": 150, "d": 938, "theta": 0, "alpha": -90},
    {"a": 0, "d": 0, "theta": 180, "alpha": 90},
    {"a": 0, "d": 200, "theta": 0, "alpha": 90}
   ]},
  "targets": {"A": [60.0, 0.0, 35.0], "SMR_2": [0, 0, 35]},
  "base": [[0, -1, 0, 2000], [1, 0, 0, 0], [0, 0, 1, -500], [0, 0, 0, 1]],
  "tracker": {"mpe_um": 15, "model": "AT960"},
  "payload_kg": 12.5
}"""


def test_spec_example_cell(tmp_path):
    cell = read_cell(put(tmp_path, "cell.json", SPEC_CELL))
    assert cell.robot == IRB2600
    assert list(cell.targets) == ["A", "B", "C"]
    np.testing.assert_array_equal(cell.targets["B"], [-30, 52, 35])
    assert cell.base is None and cell.payload_kg is None
    assert cell.tracker == {"mpe_um": 10.0, "mpe_um_per_m": 2.5}


def test_default_cell_matches_spec_example():
    a, b = default_cell(), parse_cell(SPEC_CELL)
    assert a.robot == b.robot
    assert {k: v.tolist() for k, v in a.targets.items()} == {
        k: v.tolist() for k, v in b.targets.items()
    }


def test_inline_dh_robot_equals_builtin(tmp_path):
    cell = read_cell(put(tmp_path, "cell.json", INLINE_DH))
    assert cell.robot.name == "my-arm" and cell.robot.convention == "dh"
    assert cell.robot.joints == IRB2600.joints
    assert cell.robot.parallel == IRB2600.parallel == (False, True, False, False, False, False)


def test_inline_mdh_is_the_same_arm_as_inline_dh():
    from robocal.solver.kinematics import Layout, predict

    q = np.deg2rad(np.random.default_rng(0).uniform(-60, 60, (5, 6)))
    points = []
    for text in (INLINE_DH, INLINE_MDH):
        layout = Layout(parse_cell(text).robot, np.eye(4), ("A",))
        points.append(predict(layout, layout.initial([[60, 0, 35]]), q))
    np.testing.assert_allclose(points[0], points[1], atol=1e-9)


def test_inline_mdh_robot_and_optional_keys():
    cell = parse_cell(INLINE_MDH)
    r = cell.robot
    assert r.convention == "mdh" and r.n_joints == 6
    assert r.parallel == (False, False, True, False, False, False)
    np.testing.assert_allclose(r.lower, np.deg2rad(-180))  # default limits
    np.testing.assert_allclose(r.joints[1].alpha, -np.pi / 2)
    assert list(cell.targets) == ["A", "SMR_2"]
    assert cell.base.shape == (4, 4) and cell.base[0, 3] == 2000
    assert cell.tracker == {"mpe_um": 15.0, "mpe_um_per_m": 2.5, "model": "AT960"}
    assert cell.payload_kg == 12.5


def test_cell_to_json_round_trip():
    for cell in (parse_cell(INLINE_MDH), parse_cell(SPEC_CELL)):
        back = parse_cell(json.dumps(cell_to_json(cell), indent=1))
        assert back.robot == cell.robot
        assert back.targets.keys() == cell.targets.keys()
        assert back.tracker == cell.tracker and back.payload_kg == cell.payload_kg
        if cell.base is not None:
            np.testing.assert_array_equal(back.base, cell.base)
    assert cell_to_json(default_cell())["robot"] == "irb2600"


def test_robot_json_round_trip_with_beta():
    obj = json.loads(json.dumps(robot_to_json(IRB2600)))
    assert obj["joints"][4]["limits"] == [-120.0, 120.0]
    assert "beta" in obj["joints"][1] and "beta" not in obj["joints"][0]
    assert robot_from_json(obj) == IRB2600
    # A calibrated robot: every parameter perturbed, beta non-zero on the parallel joint.
    rng = np.random.default_rng(3)
    p = IRB2600.param_vector()
    calibrated = IRB2600.with_params(p + rng.normal(0, 1e-3, p.size))
    assert calibrated.joints[1].beta != 0
    obj = json.loads(json.dumps(robot_to_json(calibrated)))
    back = robot_from_json(obj)
    assert back.parallel == calibrated.parallel
    assert [j.limits for j in back.joints] == [j.limits for j in calibrated.joints]
    # Bit-exact where a double in degrees converts back exactly; otherwise within one ulp.
    np.testing.assert_array_max_ulp(back.param_vector(), calibrated.param_vector(), maxulp=1)


def json_refusal(tmp_path, text, bad, *words):
    """Read text as cell.json; check the error's line:column points at `bad` and names `words`."""
    path = put(tmp_path, "cell.json", text)
    with pytest.raises(InputError) as info:
        read_cell(path)
    err = info.value
    assert str(err).startswith(f"{path}:{err.line}:{err.column}: "), str(err)
    line = text.splitlines()[err.line - 1]
    assert line[err.column - 1 :].startswith(bad), (str(err), line)
    for w in words:
        assert w in str(err)
    return str(err)


def swap(old, new, text=INLINE_DH):
    assert old in text
    return text.replace(old, new, 1)


def test_cell_json_syntax_error(tmp_path):
    json_refusal(
        tmp_path,
        swap('"alpha": 90, "limits": [-400', '"alpha": 90 "limits": [-400'),
        '"limits"',
        "invalid JSON",
    )


def test_cell_refusals_point_at_the_value(tmp_path):
    json_refusal(
        tmp_path, SPEC_CELL.replace('"irb2600"', '"irb9999"'), '"irb9999"', "robot:", "irb2600"
    )
    json_refusal(
        tmp_path,
        swap('"alpha": 0, "limits": [-95', '"alpha": "0", "limits": [-95'),
        '"0"',
        "robot.joints[1].alpha",
    )
    json_refusal(
        tmp_path, swap('"theta": 180', '"theta": NaN'), "NaN", "robot.joints[4].theta", "finite"
    )
    json_refusal(
        tmp_path,
        swap(
            '"a": 0, "d": 200, "theta": 0, "alpha": 0', '"a": 0, "d": 200, "theta": 0, "alpah": 0'
        ),
        '"alpah"',
        "unknown key 'alpah'",
        "did you mean 'alpha'",
    )
    json_refusal(tmp_path, swap("[-95, 155]", "[155, -95]"), "[155, -95]", "lower limit")
    json_refusal(tmp_path, swap("[-95, 155]", "[-95]"), "[-95]", "2 elements")
    json_refusal(
        tmp_path, swap('"convention": "dh"', '"convention": "DH-ish"'), '"DH-ish"', "'dh' or 'mdh'"
    )
    json_refusal(
        tmp_path,
        swap('"alpha": 90, "limits": [-120', '"alpha": 90, "beta": 0.1, "limits": [-120'),
        '"beta"',
        "joints[4].beta",
        "joint 5",
    )
    json_refusal(
        tmp_path,
        swap('{"A": [60.0, 0.0, 35.0]}', '{"A": [60.0, 0.0]}'),
        "[60.0, 0.0]",
        "targets.A",
        "3 elements",
    )
    json_refusal(
        tmp_path,
        swap('{"A": [60.0, 0.0, 35.0]}', '{"A": [1, 2, 3], "a b": [1, 2, 3]}'),
        '"a b"',
        "target name",
    )
    json_refusal(tmp_path, swap('{"A": [60.0, 0.0, 35.0]}', "{\n  }"), "{", "at least one target")
    json_refusal(
        tmp_path, SPEC_CELL.replace('"B"', '"A"'), '"A": [-30.0, 52.0', "duplicate key 'A'"
    )


def test_cell_refusals_of_optional_keys(tmp_path):
    json_refusal(
        tmp_path,
        swap("[0, -1, 0, 2000]", "[0, -1.01, 0, 2000]", INLINE_MDH),
        "[[0, -1.01",
        "base",
        "orthonormal",
    )
    json_refusal(
        tmp_path, swap("[1, 0, 0, 0]", "[-1, 0, 0, 0]", INLINE_MDH), "[[0, -1", "reflection"
    )
    json_refusal(
        tmp_path, swap("[0, 0, 0, 1]]", "[0, 0, 1, 1]]", INLINE_MDH), "[0, 0, 1, 1]", "base[3]"
    )
    json_refusal(
        tmp_path,
        swap('"payload_kg": 12.5', '"payload_kg": -1', INLINE_MDH),
        "-1",
        "payload_kg",
        "minimum",
    )
    json_refusal(
        tmp_path, swap('"mpe_um": 15', '"mpe_um": true', INLINE_MDH), "true", "tracker.mpe_um"
    )


def test_cell_missing_keys_and_no_joints(tmp_path):
    text = '{\n  "robot": "irb2600"\n}'
    msg = json_refusal(tmp_path, text, "{", "missing key 'targets'")
    assert msg.endswith(":1:1: the document: missing key 'targets'")
    json_refusal(
        tmp_path,
        '{"robot": {"convention": "dh", "joints": []}, "targets": {"A": [0, 0, 0]}}',
        "[]",
        "at least one joint",
    )
    json_refusal(tmp_path, "[1, 2]", "[1, 2]", "expected an object")
    with pytest.raises(InputError, match="empty"):
        read_cell(put(tmp_path, "cell.json", "  \n"))


def test_cell_with_bom_is_accepted(tmp_path):
    path = tmp_path / "cell.json"
    path.write_bytes(b"\xef\xbb\xbf" + SPEC_CELL.encode())
    assert isinstance(read_cell(path), Cell)


# -- model.json: every effect of the diagnosis vocabulary --------------------------------------

# the keys each effect has always been stored with: files written before must keep loading, and a
# new effect adds its own line here
# the keys each kind stores (compliance: on the nominal mass model, with the masses fitted, or both)
STORED_KEYS = {
    "joint_periodic": [{"name", "joint", "harmonic", "coef"}],
    "joint_scale": [{"name", "joint", "coef"}],
    "joint_compliance": [
        {"name", "joint", "gravity", "masses", "coef"},
        {"name", "joint", "gravity", "gravity_terms", "gravity_terms_total", "coef"},
        # the nominal mass model's torque with the driven link's masses fitted beside it
        {"name", "joint", "gravity", "masses", "gravity_terms", "gravity_terms_total", "coef"},
    ],
    "joint_backlash": [{"name", "joint", "coef"}],
    "thermal_drift": [{"name", "t_ref", "variable", "coef"}],
    "base_shift": [{"name", "at_s", "origin", "coef"}],
}


def every_effect(seed, fitted_masses: bool | None = None):
    """A model with one extension of every kind, as a diagnosis leaves them, and poses to predict
    (its compliance with the masses fitted, on the nominal mass model, or either: None)."""
    from robocal.server.formats.model_json import ModelFile
    from robocal.solver.diagnosis_report import parameters
    from robocal.solver.effects import Inputs, prepare
    from robocal.solver.kinematics import Layout, translation
    from robocal.solver.vocabulary import KINDS

    rng = np.random.default_rng(seed)
    cell = default_cell()
    m, K = 40, len(cell.targets)
    q = rng.uniform(IRB2600.lower, IRB2600.upper, (m, 6))
    time_s = np.cumsum(rng.uniform(10, 20, m))[:, None] + 2.0 * np.arange(K)
    temp_c = 20.0 + time_s / time_s.max() + rng.normal(scale=0.02, size=time_s.shape)
    inputs = Inputs(q, time_s, temp_c)
    lay = Layout(IRB2600, np.eye(4), tuple(cell.targets))
    x = lay.initial(np.array(list(cell.targets.values())))
    exts, params = [], []
    for kind in KINDS.values():
        options = kind.candidates(lay, x, inputs)
        if fitted_masses is not None and kind.name == "joint_compliance":
            options = [o for o in options if (o.masses is None) == fitted_masses]
        ext = options[rng.integers(len(options))]
        if kind.located_in_time:
            ext.at_s, ext.origin = float(np.median(time_s)), rng.normal(scale=500.0, size=3)
        ext.coef = rng.normal(scale=1e-3, size=ext.n_params)
        exts.append(ext)
        params.append(parameters(ext, prepare(ext, lay, x, inputs) if ext.is_joint else None))
    base = translation(2500.0, -400.0, 300.0)  # the robot base in the tracker frame
    model = ModelFile(
        IRB2600, base, dict(cell.targets), nominal=IRB2600, extensions=exts, parameters=params
    )
    return model, q, time_s, temp_c


@pytest.mark.parametrize("seed", range(3))
def test_every_effect_round_trips_through_model_json(tmp_path, seed):
    from robocal.server.calibration.workflow import model_predict
    from robocal.server.formats.model_json import extension_to_json, read_model, write_model
    from robocal.solver.vocabulary import KINDS

    assert set(KINDS) == set(STORED_KEYS)
    model, q, time_s, temp_c = every_effect(seed)
    write_model(tmp_path / "model.json", model)
    stored = json.loads((tmp_path / "model.json").read_text())["extensions"]
    for e in stored:
        assert set(e) - {"parameters"} in STORED_KEYS[e["name"]], e
    back = read_model(tmp_path / "model.json")
    assert [extension_to_json(e) for e in back.extensions] == [
        extension_to_json(e) for e in model.extensions
    ]
    want = model_predict(model, q, time_s, temp_c)
    np.testing.assert_allclose(model_predict(back, q, time_s, temp_c), want, atol=1e-9)
    for i in range(len(model.extensions)):  # every extension counts in the prediction
        model.extensions[i].coef = model.extensions[i].coef * 0.0
        assert np.abs(model_predict(model, q, time_s, temp_c) - want).max() > 1e-4
        model.extensions[i] = back.extensions[i]


def test_a_compliance_with_its_driven_links_masses_round_trips_and_its_sizes_are_checked(tmp_path):
    """The middle compliance variant stores the nominal masses and the driven link's terms; read
    back it predicts the same; a gravity_terms_total that does not fit the joint is refused."""
    from robocal.server.calibration.workflow import model_predict
    from robocal.server.formats.model_json import model_to_json, read_model, write_model

    model, q, time_s, temp_c = every_effect(1, fitted_masses=False)
    from robocal.solver.effects import Inputs
    from robocal.solver.kinematics import Layout
    from robocal.solver.vocabulary import KINDS

    lay = Layout(IRB2600, np.eye(4), tuple(model.targets))
    x = lay.initial(np.array(list(model.targets.values())))
    mid = next(
        c
        for c in KINDS["joint_compliance"].candidates(lay, x, Inputs(q, time_s, temp_c))
        if c.masses is not None and c.keep is not None
    )
    mid.coef = np.full(mid.n_params, 1e-3)
    model.extensions = [e for e in model.extensions if e.name != "joint_compliance"] + [mid]
    write_model(tmp_path / "model.json", model)
    stored = json.loads((tmp_path / "model.json").read_text())["extensions"][-1]
    assert set(stored) - {"parameters"} == STORED_KEYS["joint_compliance"][2], stored
    back = read_model(tmp_path / "model.json")
    np.testing.assert_array_equal(back.extensions[-1].keep, mid.keep)
    np.testing.assert_allclose(
        model_predict(back, q, time_s, temp_c), model_predict(model, q, time_s, temp_c), atol=1e-9
    )
    obj = model_to_json(model)
    obj["extensions"][-1]["gravity_terms_total"] += 4
    path = put(tmp_path, "bad.json", json.dumps(obj))
    with pytest.raises(InputError, match="gravity_terms_total"):
        read_model(path)


@pytest.mark.parametrize(
    "name, old, new, words",
    [
        (
            "thermal_drift",
            '"variable": "temp_c"',
            '"variable": "pressure"',
            "variable: expected one of",
        ),
        ("joint_backlash", '"joint": ', '"joint": 7, "was": ', "joint 7 is not one of the robot's"),
        (
            "joint_periodic",
            '"harmonic": ',
            '"harmonic": 1.5, "was": ',
            "harmonic: expected an integer",
        ),
        ("base_shift", '"at_s": ', '"was": ', "at_s"),
        (
            "joint_compliance",
            '"gravity_terms": [',
            '"gravity_terms": [99, ',
            "gravity_terms: expected indices",
        ),
        (
            "joint_compliance",
            '"gravity_terms_total": ',
            '"gravity_terms_total": 1',
            "gravity_terms_total: expected",
        ),
        ("joint_compliance", '"masses": [', '"masses": [1.0, ', "masses: expected"),
        ("joint_scale", '"coef": [', '"coef": [1.0, ', "expected 1 coefficients"),
        (
            "joint_scale",
            '"name": "joint_scale"',
            '"name": "joint_wobble"',
            "unknown extension 'joint_wobble'",
        ),
    ],
)
def test_bad_extensions_in_a_model_file_are_refused(tmp_path, name, old, new, words):
    from robocal.server.formats.model_json import model_to_json, read_model

    # a compliance on the nominal mass model stores `masses`, one with the masses fitted the rest
    model, *_ = every_effect(0, fitted_masses="masses" not in old)
    obj = model_to_json(model)
    obj["extensions"] = [e for e in obj["extensions"] if e["name"] == name]
    text = json.dumps(obj, indent=2)
    assert old in text
    path = put(tmp_path, "model.json", text.replace(old, new, 1))
    with pytest.raises(InputError, match=words) as info:
        read_model(path)
    assert str(info.value).startswith(f"{path}:") and "extensions[0]" in str(info.value)


@pytest.mark.parametrize(
    "change, field, words",
    [
        ({"schema": True}, "schema", "expected an integer, got true"),
        ({"base": [[0.0] * 4, [0.0] * 4, [0.0] * 4, [0, 0, 0, 1]]}, "base", "not orthonormal"),
        (
            {"base": [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, -1.0, 0], [0, 0, 0, 1]]},
            "base",
            "a reflection (determinant -1)",
        ),
        (
            {"base": [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 1, 1]]},
            "base",
            "[0, 0, 0, 1]",
        ),
        ({"robot": {"name": "", "convention": "dh", "joints": []}}, "robot.name", "non-empty"),
        ({"notes": json.loads("[" * 40 + "]" * 40)}, "", "too deeply"),
    ],
)
def test_model_file_refuses_what_cell_json_refuses(tmp_path, change, field, words):
    """Issue 20: a model whose base is no rotation (all zeros) was taken by predict and export;
    `schema: true` passed as 1; a document nested too deeply overflowed the reader."""
    from robocal.server.formats.model_json import model_to_json, read_model

    model, *_ = every_effect(0)
    obj = {**model_to_json(model), **change}
    path = put(tmp_path, "model.json", json.dumps(obj, indent=2))
    with pytest.raises(InputError) as info:
        read_model(path)
    message = str(info.value)
    assert message.startswith(f"{path}:") and words in message and "\n" not in message, message
    assert f": {field}" in message if field else "nested" in message, message


def test_nesting_is_bounded_at_the_parse():
    """32 levels parse; 33, or past the parser's own recursion limit, are one line naming the file."""
    from robocal.server.formats.json_doc import MAX_DEPTH, JsonDoc

    assert MAX_DEPTH == 32
    doc, value = JsonDoc.parse("x.json", "[" * 32 + "]" * 32)
    assert json.dumps(value, separators=(",", ":")) == "[" * 32 + "]" * 32
    for depth in (33, 100_000):
        for text in ("[" * depth + "]" * depth, '{"a":' * depth + "1" + "}" * depth):
            with pytest.raises(InputError, match="nested too deeply") as info:
                JsonDoc.parse("x.json", text)
            assert str(info.value).startswith("x.json:1: ")
