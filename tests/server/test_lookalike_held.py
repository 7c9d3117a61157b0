"""A small campaign fitted on half a joint's range: the periodic term the diagnosis names has
look-alikes on that joint which part past the covered range, so it is held to that range
(solver.lookalike) and the other half is no worse than geometry."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from robocal.server.bench.diagnose_suite import draw_case
from robocal.server.formats.model_doc import ExtensionDoc
from robocal.server.formats.model_json import extension_to_json
from robocal.solver.calibrate import calibrate
from robocal.solver.diagnose import diagnose
from robocal.solver.extended import predict_model
from robocal.solver.kinematics import predict
from robocal.solver.problem import Problem
from robocal.solver.vocabulary import Extension, Inputs

POSES = 200


def one_smr_half_range(seed: int, spec: str):
    """A bench cell reduced to one SMR with `spec` hidden (the notes' sim_small.py half30 case):
    30 of 200 simulated poses on one side of q2's or q3's median to fit, the other side to test;
    the joint, side and poses drawn as that harness draws them."""
    base = draw_case(seed, "clean", aim=False)
    first = sorted(base.targets)[0]
    one = {first: np.asarray(base.targets[first])}
    opts = {k: v for k, v in base.options.items() if k in ("noise_scale", "arm_scatter_deg")}
    case = replace(base, targets=one, n_poses=POSES, options=opts, specs=(spec,))
    meas = case.cell().campaign(POSES, case.cell_seed, **case.options)
    rng = np.random.default_rng([0x5B1, seed])
    rng.permutation(POSES), rng.permutation(POSES)  # the harness's two random subsets first
    q = meas.q[:, int(rng.choice([1, 2]))]
    below = q <= np.median(q)
    side = below if rng.random() < 0.5 else ~below
    train = np.sort(rng.choice(np.flatnonzero(side), 30, replace=False))
    nominal = np.array([case.targets[t] for t in meas.target_names])
    return case, meas, nominal, train, np.flatnonzero(~side)


def rms(err) -> float:
    return float(np.sqrt(np.nanmean(np.sum(np.asarray(err) ** 2, axis=-1))))


def test_a_harmonic_fitted_on_half_of_joint_3_is_held_to_the_covered_range():
    """KUKA-like arm, joint 3's second harmonic hidden, 30 poses with q3 above its median: the
    diagnosis names joint 3's first harmonic, which fits that half as well as the truth (and as
    joint 3's second harmonic or scale) and extrapolated to 2.8x geometry on the other half
    before it was held. Held at the covered range's edge: 0.75x (measured)."""
    case, meas, nominal, train, test = one_smr_half_range(7, "joint_periodic:3:2=0.016653")
    fit = meas.subset(train)
    d = diagnose(Problem.of(case.robot, nominal, fit))
    periodic = [e for e in d.extensions if e.name == "joint_periodic" and e.joint == 2]
    assert periodic and periodic[0].held is not None, [e.label() for e in d.extensions]
    lo, hi = np.degrees(periodic[0].held)
    q3 = np.degrees(meas.q[train, 2])
    assert np.isclose(lo, q3.min()) and np.isclose(hi, q3.max())
    said = d.report.stability.to_json()["held"]
    assert said and "joint 3's covered range" in said[0], said
    inputs = Inputs(meas.q[test], meas.time_s[test], meas.temp_c[test])
    diagnosed = rms(predict_model(case.robot, d.layout, d.x, d.extensions, inputs) - meas.xyz[test])
    geo = calibrate(Problem.of(case.robot, nominal, fit), "ls-sum")
    geometric = rms(predict(geo.layout, geo.x, meas.q[test]) - meas.xyz[test])
    assert diagnosed < geometric, (diagnosed, geometric)


def test_a_held_effect_keeps_its_edge_value_and_its_range_in_model_json():
    """Past the held range the scale's correction is its value at the edge; model.json keeps the
    range in degrees and reads it back."""
    e = Extension("joint_scale", joint=1, coef=np.array([1e-3]), held=np.radians([-30.0, 40.0]))
    q = np.zeros((3, 6))
    q[:, 1] = np.radians([-90.0, 10.0, 100.0])
    B = e.kind.basis(e, None, None, Inputs(q))
    assert np.allclose(B[:, 0], np.radians([-30.0, 10.0, 40.0]))
    stored = extension_to_json(e)
    assert np.allclose(stored["held_range_deg"], [-30.0, 40.0])
    back = ExtensionDoc.model_validate(stored).extension
    assert np.allclose(back.held, e.held) and np.allclose(back.coef, e.coef)
    unheld = {k: v for k, v in stored.items() if k != "held_range_deg"}
    assert ExtensionDoc.model_validate(unheld).extension.held is None
