"""Gross-outlier screening benchmark: false flags on clean campaigns, outliers found on dirty ones."""

from __future__ import annotations

import sys
import time

import numpy as np

from robocal.drivers.cell import displace


def drawn_campaign(cell, seed):
    """A campaign whose size, tracker noise (1-6x the spec), per-pose arm scatter, SMRs a pose
    and missing readings are drawn from the seed; returns (readings, measurements, description)."""
    from robocal.drivers.cell import TrackerSpec, VirtualCell

    rng = np.random.default_rng([99, seed])
    poses, noise = int(rng.choice([30, 40, 60, 100])), float(rng.uniform(1, 6))
    vc = VirtualCell.random(
        cell.robot, cell.targets, seed=seed, tracker=TrackerSpec(10 * noise, 2.5 * noise)
    )
    one, scatter = bool(rng.random() < 0.25), bool(rng.random() < 0.5)
    breaks = 0.1 if rng.random() < 0.3 else 0.0
    meas = vc.campaign(poses, seed=seed, beam_break_rate=breaks)
    xyz = meas.xyz
    if scatter:  # the arm does not return exactly: an error per pose shared by its SMRs
        dq = rng.normal(scale=np.deg2rad(rng.uniform(0.002, 0.006)), size=meas.q.shape)
        xyz = vc.measure(meas.q + dq, rng, meas.time_s, meas.temp_c)
        xyz[~np.isfinite(meas.xyz)] = np.nan
    if one:
        keep = rng.integers(0, xyz.shape[1], poses)
        drop = np.ones(xyz.shape[:2], dtype=bool)
        drop[np.arange(poses), keep] = False
        xyz[drop] = np.nan
    return (
        xyz,
        meas,
        {
            "poses": poses,
            "noise_x_spec": round(noise, 2),
            "one_smr": one,
            "arm_scatter": scatter,
            "missing": breaks,
        },
    )


def run_screen_bench(clean: int = 480, dirty: int = 240, rate: float = 0.03) -> dict:
    """Screen `clean` campaigns (any exclusion is false) and `dirty` ones with `rate` moved."""
    from robocal.solver.problem import Problem
    from robocal.solver.screen import screen_readings

    from ..formats.cell_json import default_cell

    cell = default_cell()
    out: dict = {"benchmark": "outliers", "robot": cell.robot.name}
    t0 = time.perf_counter()
    for label, n, share in (("clean", clean, 0.0), ("dirty", dirty, rate)):
        print(f"[bench] screening {n} {label} campaigns", file=sys.stderr, flush=True)
        flagged = false = found = total = 0
        missed = []
        for seed in range(n):
            xyz, meas, about = drawn_campaign(cell, seed)
            moved = np.zeros(xyz.shape[:2], dtype=bool)
            if share:
                clean_xyz = xyz
                xyz, moved = displace(xyz, seed, share)
            targets = cell.target_positions(meas.target_names)
            s = screen_readings(Problem.of(cell.robot, targets, meas).with_meas(xyz))
            wrong = int((s.excluded & ~moved).sum())
            flagged += wrong > 0
            false += wrong
            found += int((s.excluded & moved).sum())
            total += int(moved.sum())
            for p, k in np.argwhere(moved & ~s.excluded):
                missed.append(
                    {
                        "seed": seed,
                        **about,
                        "moved_mm": round(float(np.linalg.norm(xyz[p, k] - clean_xyz[p, k])), 3),
                    }
                )
        out[label] = {
            "campaigns": n,
            "with_a_false_flag": flagged,
            "false_flag_rate": flagged / n,
            "clean_readings_excluded": false,
        }
        if share:
            out[label].update(outlier_rate=share, outliers=total, found=found, missed=missed)
    out["seconds"] = round(time.perf_counter() - t0, 1)
    return out
