"""The unexplained remainder said out loud: on campaigns whose arm hides an effect outside the
vocabulary (backlash, a wrist coupling, per-pose scatter), drawn from a seed, the right covariate
ranks first; on clean campaigns no block appears and every strength stays near 0."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.solver import identifiability as ident
from robocal.solver.diagnose import Diagnoser, noise_floor
from robocal.solver.effects import Inputs
from robocal.solver.identify import register
from robocal.solver.motion import last_motion
from robocal.solver.unexplained import STRONG, Fields, covariates, unexplained
from tests.sim import default_cell
from tests.solver.test_diagnose_effects import diagnosed


class Backlash:
    """Joint J lags by b against the direction of its last move (the cell's Effect protocol)."""

    def __init__(self, joint: int, b_rad: float):
        self.joint, self.b = joint, b_rad

    def joint_offsets(self, cell, q, time_s, temp_c):
        dq = np.zeros_like(q)
        dq[:, self.joint] = -self.b * last_motion(q, time_s)[:, self.joint]
        return dq

    def base_motion(self, cell, time_s, temp_c):
        return None


class WristCoupling:
    """Joint 5 turns with joint 4: dq5 = c q4, a coupled wrist gear."""

    def __init__(self, c: float):
        self.c = c

    def joint_offsets(self, cell, q, time_s, temp_c):
        dq = np.zeros_like(q)
        dq[:, 4] = self.c * q[:, 3]
        return dq

    def base_motion(self, cell, time_s, temp_c):
        return None


class PoseScatter:
    """The arm does not return exactly: each pose's joints are off by a fresh random amount, the
    same for every SMR of the pose (repeatability)."""

    def __init__(self, sigma_rad: float, seed: int):
        self.sigma, self.rng, self.dq = sigma_rad, np.random.default_rng(seed), None

    def joint_offsets(self, cell, q, time_s, temp_c):
        if self.dq is None or self.dq.shape != q.shape:
            self.dq = self.sigma * self.rng.normal(size=q.shape)
        return self.dq

    def base_motion(self, cell, time_s, temp_c):
        return None


def campaign(seed, effect=None, poses=100, one_smr=False):
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=seed)
    if effect is not None:
        vc.effects.append(effect)
    meas = vc.campaign(poses, seed=seed)
    if one_smr:  # one SMR a pose, in turn
        K = meas.xyz.shape[1]
        drop = np.arange(K)[None, :] != (np.arange(poses) % K)[:, None]
        meas.xyz[drop] = np.nan
        meas.time_s[drop] = meas.temp_c[drop] = np.nan
    return cell, vc, meas


def geometric_remainder(cell, meas):
    """The geometric model's held-out residual and what unexplained() needs beside it."""
    targets = cell.target_positions(meas.target_names)
    prob, x0 = register(cell.robot, targets, meas.target_names, meas.q, meas.xyz, cell.base)
    st = ident.structural(prob.layout, x0, np.ones(prob.layout.n_params, dtype=bool))
    inputs = Inputs(meas.q, meas.time_s, meas.temp_c)
    cv = Diagnoser(prob, x0, st.free, inputs).cross_validate([])
    x, exts = cv.fits["all"]
    return cv, prob.layout, x, exts, inputs, noise_floor(meas.xyz, inputs)


def strengths(cell, meas):
    """Every covariate's strength on the geometric model's held-out residual."""
    cv, layout, x, exts, inputs, _ = geometric_remainder(cell, meas)
    mask = np.all(np.isfinite(cv.resid), axis=-1)
    return covariates(Fields(layout, x, exts, inputs, mask), cv.resid[mask], np.nonzero(mask)[0])


def aimed(seed, make, target):
    """The effect whose geometric held-out RMS is about `target` times the noise floor: the excess
    variance grows with the square of the magnitude, so one probe fixes the scale."""
    probe = 1.0
    for _ in range(4):
        cell, vc, meas = campaign(seed, make(probe))
        cv = geometric_remainder(cell, meas)[0]
        ratio = cv.rmse / vc.noise_floor_mm(meas.q)
        if ratio > 2.0:
            break
        probe *= 4.0
    return make(probe * np.sqrt(target**2 - 1.0) / np.sqrt(ratio**2 - 1.0))


def draw(seed):
    """An effect outside the vocabulary, its size (3-15x the floor) and the covariate and channel
    that must rank first, all from the seed."""
    rng = np.random.default_rng(seed)
    target = float(np.exp(rng.uniform(np.log(3.0), np.log(15.0))))
    if rng.uniform() < 0.6:
        joint = int(rng.integers(0, 6))
        effect = aimed(seed, lambda s: Backlash(joint, np.radians(0.005) * s), target)
        return effect, f"direction of joint {joint + 1}'s last motion", f"joint {joint + 1}"
    sign = float(rng.choice([-1.0, 1.0]))
    effect = aimed(seed, lambda s: WristCoupling(sign * 1e-5 * s), target)
    return effect, "joint 4's angle", "joint 5"


@pytest.mark.parametrize("seed", range(10))
def test_hidden_effect_ranks_its_covariate_first(seed):
    effect, name, channel = draw(seed)
    cell, _, meas = campaign(seed, effect)
    cv, layout, x, exts, inputs, floor = geometric_remainder(cell, meas)
    block = unexplained(cv.resid, layout, x, exts, inputs, floor, cv.mse)
    assert block is not None, f"{name}: held-out {cv.rmse:.4f} mm, floor {floor:.4f} mm"
    top = block["covariates"][0]
    assert (top["name"], top["channel"]) == (name, channel), block["covariates"][:3]
    assert top["strength"] > 0.5, top
    assert block["share_of_baseline_mse"] == pytest.approx(1.0)
    if name.startswith("direction"):
        assert "backlash" in top["reading"], top["reading"]
    else:
        assert "coupling between joints 4 and 5" in top["reading"], top["reading"]
    # a joint's error moves all SMRs of a pose together, but a covariate explains it
    assert block["per_pose_share"] > 0.5 and not block["per_pose_dominates"]


@pytest.mark.parametrize("seed,poses", [(s, (30, 60, 100)[s % 3]) for s in range(100, 109)])
def test_clean_campaign_gets_no_block_and_weak_strengths(seed, poses):
    cell, _, meas = campaign(seed, poses=poses)
    d = diagnosed(cell, meas)
    assert d.report.unexplained is None, d.report.unexplained
    top = max(strengths(cell, meas), key=lambda c: c["strength"])
    # the best of ~140 covariate-channel pairs on 30 poses reaches about 0.1 by chance (measured)
    assert top["strength"] < (2 if poses < 60 else 1) * STRONG, top


def test_wrist_coupling_is_reported_by_the_diagnosis():
    """Through diagnose() itself: nothing in the vocabulary models the coupling, so it is left,
    and the block names it."""
    effect, name, channel = draw(1)
    assert name == "joint 4's angle"  # seed 1 draws the coupling
    cell, _, meas = campaign(1, effect)
    d = diagnosed(cell, meas)
    block = d.report.unexplained
    assert block["holdout_rmse_mm"] == pytest.approx(d.report.final.holdout_rmse_mm)
    assert block["noise_floor_ratio"] > 1.5
    assert (block["covariates"][0]["name"], block["covariates"][0]["channel"]) == (name, channel)
    assert block["reading"].startswith("Unexplained: ")


@pytest.mark.parametrize("seed", range(200, 204))
def test_one_smr_a_pose_reports_only_what_a_covariate_explains(seed):
    """No noise floor without two SMRs a pose: the block appears only when a covariate explains
    the remainder on left-out poses."""
    rng = np.random.default_rng(seed)
    joint = int(rng.integers(0, 3))
    for effect in (None, Backlash(joint, np.radians(rng.uniform(0.01, 0.03)))):
        cell, _, meas = campaign(seed, effect, one_smr=True)
        cv, layout, x, exts, inputs, floor = geometric_remainder(cell, meas)
        assert floor is None
        block = unexplained(cv.resid, layout, x, exts, inputs, floor, cv.mse)
        if effect is None:
            assert block is None, block
        else:
            assert block is not None and block["noise_floor_ratio"] is None
            assert block["covariates"][0]["name"] == f"direction of joint {joint + 1}'s last motion"
            assert "per_pose_share" not in block  # one SMR: no rigid motion per pose to measure


@pytest.mark.parametrize("seed", range(300, 303))
def test_per_pose_scatter_is_said_to_dominate(seed):
    """Random joint errors fresh at every pose (0.003-0.006 deg): well above the floor, shared by
    the SMRs of a pose, and no covariate explains them."""
    sigma = np.radians(np.random.default_rng(seed).uniform(0.003, 0.006))
    cell, _, meas = campaign(seed, PoseScatter(sigma, seed))
    cv, layout, x, exts, inputs, floor = geometric_remainder(cell, meas)
    block = unexplained(cv.resid, layout, x, exts, inputs, floor, cv.mse)
    assert block is not None
    assert block["per_pose_dominates"], block
    assert block["covariates"][0]["strength"] < STRONG
    assert "repeatability" in block["per_pose_reading"]
    assert "per-pose error" in block["reading"]


@pytest.mark.parametrize("seed", (21, 24))
def test_no_block_once_the_hidden_effect_is_named(seed):
    """An effect of the vocabulary, drawn as tests/server/test_diagnose.py draws it: the diagnosis
    names it, the final model reaches the floor, and nothing is left to say."""
    from robocal.drivers.effects import make_effects
    from tests.solver.test_diagnose_effects import aim
    from tests.solver.test_diagnose_effects import draw as draw_vocabulary

    spec, name, _, _, target = draw_vocabulary(seed)
    cell = default_cell()
    magnitude = aim(cell, spec, name, seed, target)
    vc = VirtualCell.random(cell.robot, cell.targets, seed=seed)
    vc.effects.extend(make_effects([f"{spec}={magnitude:.6g}"], vc, seed))
    meas = vc.campaign(100, seed=seed)
    d = diagnosed(cell, meas)
    assert [e.name for e in d.report.effects] == [name]
    assert d.report.unexplained is None, d.report.unexplained


class Together:
    """Two effects at once."""

    def __init__(self, *effects):
        self.effects = effects

    def joint_offsets(self, cell, q, time_s, temp_c):
        return sum(e.joint_offsets(cell, q, time_s, temp_c) for e in self.effects)

    def base_motion(self, cell, time_s, temp_c):
        return None


@pytest.mark.parametrize("seed", (400, 401, 402))
def test_two_hidden_effects_are_the_first_two(seed):
    """Backlash in one of joints 1-3 and a wrist coupling, sizes from the seed: both lead the list,
    each judged beside the one above it, and what follows is weak."""
    rng = np.random.default_rng(seed)
    joint = int(rng.integers(0, 3))
    both = Together(
        Backlash(joint, np.radians(rng.uniform(0.003, 0.006))),
        WristCoupling(rng.choice([-1, 1]) * rng.uniform(3e-5, 6e-5)),
    )
    cell, _, meas = campaign(seed, both)
    cv, layout, x, exts, inputs, floor = geometric_remainder(cell, meas)
    covs = unexplained(cv.resid, layout, x, exts, inputs, floor, cv.mse)["covariates"]
    assert {(c["name"], c["channel"]) for c in covs[:2]} == {
        (f"direction of joint {joint + 1}'s last motion", f"joint {joint + 1}"),
        ("joint 4's angle", "joint 5"),
    }, covs[:3]
    assert covs[2]["strength"] < 0.05, covs[2]
    assert "a further" in covs[1]["reading"]


@pytest.mark.parametrize("ratio,shown", [(1.49, False), (1.51, True)])
def test_the_block_appears_exactly_above_one_and_a_half_times_the_floor(ratio, shown):
    """The rule the report states: a block whenever the held-out RMS exceeds 1.5x the floor, on
    either side of it by 1% (a 30-pose campaign: what a correct model reaches held out is above
    the floor there, which once kept the block away up to 1.6x)."""
    cell, _, meas = campaign(7, poses=30)
    cv, layout, x, exts, inputs, _ = geometric_remainder(cell, meas)
    mask = np.all(np.isfinite(cv.resid), axis=-1)
    rmse = float(np.sqrt(np.mean(np.sum(cv.resid[mask] ** 2, axis=-1))))
    block = unexplained(cv.resid, layout, x, exts, inputs, rmse / ratio, cv.mse)
    assert (block is not None) is shown, block
    if shown:
        assert block["noise_floor_ratio"] == pytest.approx(ratio)
        assert block["reachable_mm"] > rmse / ratio  # said, no longer a gate
