"""A check's payload change on an arm whose base is turned relative to the tracker (wall- or
ceiling-mounted): gravity is the levelled tracker's -z, as the solver's compliance takes it
(solver.gravity.gravity_in_base), not the base's -z."""

import numpy as np
import pytest

from robocal.server.checks import check
from robocal.server.cli import main as robocal
from robocal.server.formats.model_json import read_model
from robocal.solver.gravity import gravity_in_base
from robocal.solver.kinematics import Layout, joint_frames, predict
from robocal.solver.measurements import Measurements


def _turned(deg: float, axis: int) -> np.ndarray:
    """A rotation of the tracker frame: the arm's base turned `deg` about tracker axis `axis`."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i, j = [a for a in range(3) if a != axis]
    W = np.eye(4)
    W[i, i], W[i, j], W[j, i], W[j, j] = c, -s, s, c
    return W


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    d = tmp_path_factory.mktemp("gravity")
    assert robocal(["simulate", "--poses", "25", "--seed", "8", "--out", str(d / "m.csv")]) == 0
    out = d / "model.json"
    assert robocal(["calibrate", str(d / "m.csv"), "--method", "ls-sum", "--out", str(out)]) == 0
    return out


def _heavier(model, q: np.ndarray, compliance: np.ndarray) -> np.ndarray:
    """The SMRs where the arm puts them once a weight at their centre bends each joint by
    compliance x its gravity torque, gravity taken as the solver's compliance takes it."""
    lay, x = model.layout()
    in_base = Layout(lay.robot, np.eye(4), lay.target_names)
    g = gravity_in_base(lay, x)
    centre = predict(in_base, x, q).mean(axis=1)
    torque = np.stack(
        [
            np.einsum("mi,mi->m", R[:, :, 2], np.cross(centre - o, g))
            for R, o in joint_frames(in_base, x, q)
        ],
        axis=1,
    )  # (m, N) mm: per N of weight
    return predict(lay, x, q + compliance * torque)


@pytest.mark.parametrize("mount", ["floor", "wall", "ceiling", "tilted 30 deg"])
def test_a_payload_change_is_named_on_a_turned_base(model_path, mount):
    """Before, the check's payload columns took gravity along the base's -z: on a wall-mounted
    arm the heavier tool's sag was blamed on nothing ('unknown') or on another cause."""
    turn = {"floor": np.eye(4), "wall": _turned(90, 0), "ceiling": _turned(180, 0)}
    W = turn.get(mount, _turned(30, 1))
    model = read_model(model_path)
    model.base = W @ model.base
    rng = np.random.default_rng(3)
    robot = model.robot
    q = rng.uniform(robot.lower, robot.upper, size=(10, robot.n_joints)) * 0.6
    compliance = np.zeros(robot.n_joints)
    compliance[1:3] = 2e-7  # rad per N mm: joints 2 and 3 give way (tenths of a mm)
    xyz = _heavier(model, q, compliance)
    names = tuple(model.targets)
    meas = Measurements([f"c{i}" for i in range(len(q))], q, names, xyz)
    r = check._readings(model, meas, "check.csv")
    rms = float(np.sqrt(np.mean(np.sum(r.error**2, axis=1))))
    new, _, cause = check.judge(model, r, [], 0.01)
    print(f"\n{mount}: {rms:.3f} mm RMS -> {new.verdict}, cause {cause}: {new.reason}")
    assert new.verdict == "recalibrate" and cause == "payload", new.reason
