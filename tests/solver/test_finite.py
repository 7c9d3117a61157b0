"""Non-finite or absurdly large data is refused with a clear ValueError before any LAPACK call
(whose SVD may never return on inf), at the entry points and, when those are bypassed, at the
intermediate products that overflow."""

from __future__ import annotations

import numpy as np
import pytest

import robocal.solver.finite
from robocal.drivers.cell import VirtualCell
from robocal.solver.calibrate import calibrate
from robocal.solver.diagnose import diagnose
from robocal.solver.finite import NonFinite
from robocal.solver.problem import Problem
from robocal.solver.rigid import kabsch
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS
from tests.sim import in_child

NAMES = ("A", "B", "C")
METHODS = ["nominal", "ls-sum", "ls-single:A", "ls-pose", "minimax"]
CHILD_LIMIT_S = 120  # a regression would hang in LAPACK: in a child process, killed past this


def campaign(seed=4, poses=30):
    cell = VirtualCell.random(IRB2600, TARGETS, seed=seed)
    meas = cell.campaign(poses, seed=seed + 1000)
    return np.array([TARGETS[t] for t in NAMES]), meas


def huge(value=1e308):
    targets, meas = campaign()
    xyz = meas.xyz.copy()
    xyz[0, 0, 0] = value
    return targets, meas.q, xyz


@pytest.mark.parametrize("method", METHODS)
def test_every_method_refuses_a_coordinate_beyond_any_instrument(method):
    targets, q, xyz = huge()
    with pytest.raises(NonFinite, match=r"measured SMR positions: a coordinate of 1e\+308 mm"):
        calibrate(Problem(IRB2600, targets, NAMES, q, xyz), method)


def test_diagnose_refuses_it_too():
    targets, q, xyz = huge()
    with pytest.raises(NonFinite, match="beyond"):
        diagnose(Problem(IRB2600, targets, NAMES, q, xyz))


def test_inf_and_nan_are_named_but_a_missing_reading_is_not():
    targets, meas = campaign()
    xyz, q = meas.xyz.copy(), meas.q.copy()
    xyz[1, 2, 1] = np.inf
    with pytest.raises(NonFinite, match="non-finite values in the measured SMR positions"):
        calibrate(Problem(IRB2600, targets, NAMES, meas.q, xyz), "ls-sum")
    q[3, 2] = np.nan
    with pytest.raises(NonFinite, match="non-finite values in the joint angles"):
        calibrate(Problem(IRB2600, targets, NAMES, q, meas.xyz), "ls-sum")
    xyz = meas.xyz.copy()
    xyz[1, 2] = np.nan  # a beam break: the fit goes on without it
    assert calibrate(Problem(IRB2600, targets, NAMES, meas.q, xyz), "ls-sum").x.size


def test_the_registration_refuses_an_overflowing_cross_covariance():
    src = np.random.default_rng(0).normal(size=(10, 3)) * 1000
    dst = src.copy()
    dst[0] = 1e308  # finite, but (dst - mean)' (src - mean) overflows to inf
    with (
        np.errstate(over="ignore"),
        pytest.raises(NonFinite, match="registration's cross-covariance"),
    ):
        kabsch(src, dst)


def _without_entry_bound(what: str, value: float) -> str:
    """In a child: the fit with the entry bound lifted; the error it ended with, or "ok"."""
    robocal.solver.finite.MAX_MM = np.inf
    targets, q, xyz = huge(value)
    try:
        if what == "diagnose":
            diagnose(Problem(IRB2600, targets, NAMES, q, xyz), screen_outliers=False)
        else:
            calibrate(Problem(IRB2600, targets, NAMES, q, xyz), what)
    except NonFinite as e:
        return str(e)
    return "ok"


@pytest.mark.parametrize("what", METHODS + ["diagnose"])
def test_without_the_entry_bound_the_intermediate_checks_still_refuse(what):
    # 1e308 overflows in the registration; 1e200 gets further (its squares overflow) and is
    # fitted or refused by the checks in front of the QP, the pose fit or the normal equations.
    message = in_child(_without_entry_bound, (what, 1e308), CHILD_LIMIT_S)
    assert message.startswith("non-finite values in "), message
    message = in_child(_without_entry_bound, (what, 1e200), CHILD_LIMIT_S)
    assert message == "ok" or message.startswith("non-finite values in "), message
