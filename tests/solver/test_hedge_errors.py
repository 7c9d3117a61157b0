"""The half-way model's standard errors (solver.hedge.half_way_errors) are its own: over repeated
campaigns on the same poses, the spread of geometry's and the extended fit's average (the effect
at half its fitted size) matches the standard errors reported for it."""

from types import SimpleNamespace

import numpy as np

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.solver import identifiability as ident
from robocal.solver.diagnosis_report import parameters
from robocal.solver.effects import Extension, Inputs, joint_basis
from robocal.solver.extended import fit_extended
from robocal.solver.fit_errors import effect_uncertainty, extended_errors
from robocal.solver.hedge import half_way_errors, halved
from robocal.solver.identify import register
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS
from tests.solver.test_uncertainty import DRAWS, assert_honest

KEYS = ("amplitude_deg", "phase_deg")
# a weak effect (8x its half-way amplitude's error), as the hedge deploys; with a strong one the
# geometric fit's lack of fit enters its sandwich as noise, and the average's errors err large
MAGNITUDE_DEG = 0.001


def draws(magnitude, seed=21, poses=40):
    """Per draw: the half-way model's values (the arm's parameters, the halved effect's amplitude,
    phase and coefficients), its reported standard errors, and those the whole estimator gives
    at the half-way point (the former report's)."""
    vc = VirtualCell.random(IRB2600, TARGETS, seed=seed)
    vc.effects.extend(make_effects([f"joint_periodic:3:1={magnitude}"], vc, seed))
    rng = np.random.default_rng(seed)
    q = vc.sample_poses(poses, rng)
    targets = np.array([TARGETS[k] for k in vc.target_names])
    ext = Extension("joint_periodic", joint=2, harmonic=1)
    values, ses, former = [], [], []
    for _ in range(DRAWS):
        xyz = vc.measure(q, rng)
        prob, x0 = register(IRB2600, targets, vc.target_names, q, xyz)
        free = ident.structural(prob.layout, x0, np.ones(prob.layout.n_params, bool)).free
        inputs = Inputs(q)
        x_geo, _, _ = fit_extended(prob, inputs, x0, free, [])
        x_ext, ee, _ = fit_extended(prob, inputs, x0, free, [ext])
        xh, eh = halved(ee, x_ext, x_geo)
        diag = SimpleNamespace(prob=prob, inputs=inputs, x0=x0, free=free, prior=None)
        basis = joint_basis(eh[0], prob.layout, x0, inputs)
        p = parameters(eh[0], basis)
        arm = np.flatnonzero(free[: prob.layout.n_geo])  # the base moves with each registration
        row = [p[k] for k in KEYS] + list(eh[0].coef) + list(xh[arm])
        values.append(row)
        for out, err in (
            (ses, half_way_errors(diag, x_geo, x_ext, ee)),
            (former, extended_errors(prob, inputs, x0, free, xh, eh)),
        ):
            u = effect_uncertainty(err, eh, 0, basis, parameters)
            coef = np.sqrt(np.diag(err.block([f"{eh[0].label()}[{i}]" for i in range(2)])))
            out.append([u[k] for k in KEYS] + list(coef) + list(err.internal()[arm]))
    return np.array(values), np.array(ses), np.array(former)


def test_the_half_way_models_standard_errors_match_its_spread():
    """The halved coefficients' errors are half the whole fit's, the phase's unchanged, the
    averaged parameters' carry the two fits' cross-covariance: all match the spread. The whole
    estimator taken at the half-way point (the former report) gave the effect's amplitude, phase
    and coefficients errors two to three times their spread."""
    values, ses, former = draws(MAGNITUDE_DEG)
    sd = values.std(axis=0, ddof=1)
    ratio = sd / np.sqrt(np.mean(ses**2, axis=0))
    assert_honest(ratio)
    was = sd / np.sqrt(np.mean(former**2, axis=0))
    assert was[:4].max() < 0.6, was[:4]  # amplitude, phase, both coefficients


if __name__ == "__main__":
    import sys

    v, s, f = draws(float(sys.argv[1]))
    sd = v.std(axis=0, ddof=1)
    print(np.round(sd / np.sqrt(np.mean(s**2, axis=0)), 2))
    print(np.round(sd / np.sqrt(np.mean(f**2, axis=0)), 2))
    print("amplitude mean", v[:, 0].mean(), "se", s[:, 0].mean())
