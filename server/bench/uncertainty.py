"""The position uncertainty's coverage through the program's own path: per arm (the IRB 2600,
a KUKA-like arm and a random 6R arm with a ring of SMRs) and seed, a simulated campaign with an
effect (the model's own; with the arm's scatter too; or with a weaker one besides that no model
names), diagnosed by `robocal diagnose` (the extended model: effects named by the diagnosis) and
calibrated by ls-sum (the geometric model, the reference measured in the same run), each
written to model.json and read back; the fraction of independent positions' true errors within
the U that model.json's block states (95 % asked)."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

ARMS = ("irb2600", "kuka-like", "random")
KINDS = ("effect", "scatter", "extra")
EFFECTS = ("joint_compliance:2=0.3", "joint_periodic:3=0.01", "joint_compliance:3=0.3")
UNMODELLED = "joint_periodic:2=0.004"
SCATTER_DEG = 0.003
POSES, TEST_POSES = 60, 20


def _covered(model_path, vc, q, truth) -> np.ndarray | None:
    """Per test reading, whether its true error is within U; None if the model states no U."""
    from robocal.server.calibration.position_uncertainty import model_uncertainty
    from robocal.server.compensate.compensation import solver_model
    from robocal.server.formats.model_json import read_model

    model = read_model(model_path)
    u = model_uncertainty(model, q)
    if u is None:
        return None
    err = np.linalg.norm(solver_model(model).predict(q) - truth, axis=-1)
    return (err <= u.expanded_mm).ravel()


def run_case(arm: str, seed: int, folder: Path) -> dict:
    """One campaign's coverage by the diagnosed and the ls-sum model."""
    from robocal.drivers.cell import VirtualCell
    from robocal.drivers.effects import make_effects
    from robocal.server.calibration import workflow
    from robocal.server.formats.model_json import write_model

    from .adaptive import arm_cell

    kind = KINDS[seed % len(KINDS)]
    cell = arm_cell(arm, seed)
    vc = VirtualCell.random(cell.robot, dict(cell.targets), seed=seed)
    specs = [EFFECTS[seed % len(EFFECTS)]] + ([UNMODELLED] if kind == "extra" else [])
    vc.effects = make_effects(specs, vc, seed)
    scatter = SCATTER_DEG if kind == "scatter" else 0.0
    meas = vc.campaign(POSES, seed, arm_scatter_deg=scatter)
    rng = np.random.default_rng([7, seed])
    q = vc.sample_poses(TEST_POSES, rng)
    truth = vc.true_points(q, pose_dq=np.deg2rad(scatter) * rng.normal(size=q.shape))
    _, extended = workflow.diagnose(cell, meas)
    write_model(folder / "extended.json", extended)
    geometric = workflow.model_file(workflow.run_method(cell, meas, "ls-sum"), cell, meas)
    write_model(folder / "geometric.json", geometric)
    return {
        "arm": arm,
        "seed": seed,
        "kind": kind,
        "effects_named": [e.label() for e in extended.extensions],
        "extended": _covered(folder / "extended.json", vc, q, truth),
        "geometric": _covered(folder / "geometric.json", vc, q, truth),
    }


def _share(cases: list[dict], which: str, kind: str | None = None) -> float | None:
    hits = [c[which] for c in cases if c[which] is not None and kind in (None, c["kind"])]
    return round(float(np.mean(np.concatenate(hits))), 4) if hits else None


def run_uncertainty_bench(seeds: int = 20, arms=ARMS) -> dict:
    """Coverage of U over seeds x arms diagnosed and ls-sum models."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        cases = [run_case(arm, seed, Path(d)) for seed in range(seeds) for arm in arms]
    return {
        "asked": 0.95,
        "models": len(cases),
        "test_positions_per_model": TEST_POSES,
        **{
            which: {
                "coverage": _share(cases, which),
                "by_kind": {k: _share(cases, which, k) for k in KINDS},
                "without_U": sum(c[which] is None for c in cases),
            }
            for which in ("extended", "geometric")
        },
        "with_effects_named": sum(bool(c["effects_named"]) for c in cases),
        "wall_s": round(time.perf_counter() - t0, 1),
    }
