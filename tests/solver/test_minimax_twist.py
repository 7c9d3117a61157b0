"""minimax from the twist normal equations (no Jacobian) equals the full-Jacobian path: the same
derivatives at every point, the same optimum on the method tests' campaigns."""

import functools

import numpy as np
import pytest

from robocal.solver import calibrate as calibrate_module
from robocal.solver import minimax as minimax_module
from robocal.solver.robot import IRB2600
from tests.robots import KUKA_LIKE, PUMA_LIKE
from tests.solver.test_methods import campaign, fit

ROBOTS = {"irb2600": IRB2600, "kuka-like": KUKA_LIKE, "puma-like": PUMA_LIKE}


def both(robot, meas, monkeypatch, **kw):
    """The minimax calibration by each path."""
    out = {"twist": fit(robot, meas, "minimax", **kw)}
    full = functools.partial(minimax_module.minimax, derivatives="full")
    monkeypatch.setattr(calibrate_module, "minimax", full)
    out["full"] = fit(robot, meas, "minimax", **kw)
    return out


@pytest.mark.parametrize(("name", "seed"), [("irb2600", 1), ("kuka-like", 2), ("puma-like", 3)])
def test_the_same_optimum_as_the_full_jacobian(name, seed, monkeypatch):
    robot = ROBOTS[name]
    _, cal, _ = campaign(robot, seed)
    out = both(robot, cal, monkeypatch)
    a, b = out["twist"].F.max(), out["full"].F.max()
    assert abs(a - b) <= 1e-8 * b, (a, b)
    assert out["twist"].success and out["twist"].qp_converged, out["twist"].message
    np.testing.assert_allclose(out["twist"].F, out["full"].F, rtol=1e-6)


def test_missing_readings_and_the_derivatives_themselves(monkeypatch):
    _, cal, _ = campaign(IRB2600, 7, n_cal=60)
    rng = np.random.default_rng(7)
    cal.xyz[rng.random(cal.xyz.shape[:2]) < 0.15] = np.nan  # beam breaks, some poses partial
    out = both(IRB2600, cal, monkeypatch)
    a, b = out["twist"].F.max(), out["full"].F.max()
    assert abs(a - b) <= 1e-8 * b, (a, b)

    # at the problem calibrate hands minimax, at its start and away from it: every derivative
    seen = {}

    def record(prob, x, free, rows=None, **kw):
        seen.update(prob=prob, x=x, free=free, rows=rows)
        return minimax_module.minimax(prob, x, free, rows=rows, **kw)

    monkeypatch.setattr(calibrate_module, "minimax", record)
    fit(IRB2600, cal, "minimax")
    rows = seen["rows"] if seen["rows"] is not None else [0, 1, 2]
    objs = [
        minimax_module._Objective(seen["prob"], seen["x"], seen["free"], rows, None, d)
        for d in ("twist", "full")
    ]
    z = rng.normal(scale=1e-3, size=int(np.sum(seen["free"])))
    for point in (None, z):
        got = [o(point) for o in objs]
        for u, v in zip(got[0], got[1]):
            if v is None:  # J'J: at the start only
                assert u is None and point is not None
                continue
            np.testing.assert_allclose(u, v, rtol=1e-9, atol=1e-9 * np.abs(v).max())
