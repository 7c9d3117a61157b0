"""The solver's entry points leave their inputs alone: they run on read-only arrays, unchanged."""

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.solver.calibrate import METHODS, calibrate
from robocal.solver.identify import register
from robocal.solver.kinematics import Layout, predict, predict_rows, predict_with_jacobian
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS

NAMES = ("A", "B", "C")


def _frozen(*arrays):
    out = []
    for a in arrays:
        a = np.array(a, dtype=float)
        a.flags.writeable = False
        out.append(a)
    return out


@pytest.fixture(scope="module")
def inputs():
    cell = VirtualCell.random(IRB2600, TARGETS, seed=5)
    meas = cell.campaign(60, seed=6)
    xyz = np.array(meas.xyz)
    xyz[3, 1] = np.nan  # a missing reading: the solvers mask it, never fill it in
    targets = np.array([TARGETS[t] for t in NAMES])
    return _frozen(targets, meas.q, xyz, cell.base)


@pytest.mark.parametrize("method", [*(m for m in METHODS if m != "ls-single"), "ls-single:B"])
def test_calibrate_runs_on_read_only_inputs_and_leaves_them_unchanged(inputs, method):
    targets, q, xyz, _ = inputs
    copies = [a.copy() for a in (targets, q, xyz)]
    cal = calibrate(Problem(IRB2600, targets, NAMES, q, xyz), method)
    assert np.all(np.isfinite(cal.x))
    for a, c in zip((targets, q, xyz), copies, strict=True):
        np.testing.assert_array_equal(a, c)


def test_register_and_predict_leave_their_inputs_unchanged(inputs):
    targets, q, xyz, base = inputs
    copies = [a.copy() for a in (targets, q, xyz, base)]
    for guess in (None, base):
        prob, x0 = register(IRB2600, targets, NAMES, q, xyz, base_guess=guess)
    (x,) = _frozen(x0)
    lay = prob.layout
    p = predict(lay, x, q)
    p2, J, Jq = predict_with_jacobian(lay, x, q)
    mask = np.all(np.isfinite(xyz), axis=-1)
    _, Jt = predict_rows(lay, x, q, mask, np.arange(lay.n_params))
    np.testing.assert_array_equal(p, p2)
    assert Jt.shape == (lay.n_params, int(mask.sum()), 3)
    for a, c in zip((targets, q, xyz, base), copies, strict=True):
        np.testing.assert_array_equal(a, c)


def test_start_fit_does_not_move_its_normal_equations_layout(inputs):
    from robocal.solver.normal import PointNormal

    targets, q, xyz, _ = inputs
    lay = Layout(IRB2600, np.eye(4), NAMES)
    mask = np.all(np.isfinite(xyz), axis=-1)
    points = PointNormal(lay, q, mask, xyz, np.arange(lay.n_params))
    moved, _ = points.register(lay.initial(targets))
    assert points.layout is lay and moved.layout is not lay
    assert not np.allclose(moved.layout.base_ref, np.eye(4))
