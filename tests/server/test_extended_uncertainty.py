"""A diagnosed (extended) model keeps its position uncertainty: model.json's block covers the
extension's coefficients as well as the geometry, read back it gives U at any joints, and that U
holds the true error of independent positions about as often as it states."""

from __future__ import annotations

import numpy as np

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.server.calibration import workflow
from robocal.server.calibration.position_uncertainty import model_uncertainty
from robocal.server.compensate.compensation import solver_model
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.model_json import read_model, write_model


def test_a_diagnosed_models_block_covers_its_extension(tmp_path):
    cell = default_cell()
    vc = VirtualCell.random(cell.robot, dict(cell.targets), seed=3)
    vc.effects = make_effects(["joint_compliance:2=0.3"], vc, 3)
    _, model = workflow.diagnose(cell, vc.campaign(60, 3))
    assert [e.name for e in model.extensions] == ["joint_compliance"]
    write_model(tmp_path / "model.json", model)
    back = read_model(tmp_path / "model.json")
    block = back.uncertainty.position
    coefs = [p for p in block["parameters"] if p.startswith("joint_compliance")]
    assert len(coefs) == len(model.extensions[0].coef) and "a2" in block["parameters"]
    q = vc.sample_poses(200, np.random.default_rng(1))
    u = model_uncertainty(back, q)
    assert u is not None and np.all(u.parameters_mm > 0)
    err = np.linalg.norm(solver_model(back).predict(q) - vc.true_points(q), axis=-1)
    covered = float(np.mean(err <= u.expanded_mm))
    print(f"\none diagnosed model: {covered:.3f} of 600 positions within U")
    assert 0.9 <= covered <= 0.995
