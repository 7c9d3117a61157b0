"""The quick check's statistics (solver.drift): a clean arm's histories almost never trip
`recalibrate`, small lasting changes trip it within a couple of checks, and a change is named
only when one cause alone explains it."""

from __future__ import annotations

import numpy as np

from robocal.solver import drift

POSES = 6


def run_history(rng, sigma, n_checks, shift_from=None, shift=None, bias=None):
    """Verdicts of a history of checks: per pose a fixed model error plus fresh scatter (each
    pose its own scatter, sigma (P,) mm 3-D), a shift (P, 3) added from check shift_from on."""
    bias = rng.normal(scale=0.05, size=(POSES, 3)) if bias is None else bias
    past: list[np.ndarray] = []
    stats: list[tuple[float, float]] = []
    verdicts = []
    for k in range(n_checks):
        now = bias + rng.normal(size=(POSES, 3)) * (sigma / np.sqrt(3.0))[:, None]
        if shift_from is not None and k >= shift_from:
            now = now + shift
        c = drift.since_baseline(now, np.array(past).reshape(-1, POSES, 3), stats, 0.03)
        stats.append((c.z, c.cusum) if c else (0.0, 0.0))
        verdicts.append(c.verdict if c else "ok")
        past.append(now)
    return verdicts


def test_clean_histories_almost_never_say_recalibrate():
    rng = np.random.default_rng(0)
    verdicts = []
    for _ in range(120):
        # the arm's scatter differs by pose (reach) and from the 0.03 mm guess, either way
        sigma = rng.uniform(0.01, 0.06) * rng.uniform(0.6, 1.4, POSES)
        verdicts += run_history(rng, sigma, 25)
    rate = verdicts.count("recalibrate") / len(verdicts)
    print(f"\nfalse recalibrate {rate:.4f}, watch {verdicts.count('watch') / len(verdicts):.3f}")
    assert rate <= 0.01


def test_a_lasting_change_trips_within_two_checks():
    rng = np.random.default_rng(1)
    delays = []
    for _ in range(60):
        sigma = np.full(POSES, 0.03)
        direction = rng.normal(size=3)
        shift = np.tile(0.08 * direction / np.linalg.norm(direction), (POSES, 1))
        v = run_history(rng, sigma, 12, shift_from=8, shift=shift)
        tripped = [k for k in range(8, 12) if v[k] == "recalibrate"]
        delays.append(tripped[0] - 7 if tripped else 99)
    print(f"\nmedian delay {np.median(delays)}, worst {max(delays)}")
    assert np.median(delays) <= 2 and max(delays) <= 4


def test_a_change_is_named_only_when_one_cause_alone_explains_it():
    rng = np.random.default_rng(2)
    points = rng.uniform(-800, 800, size=(POSES, 3))
    joint = rng.normal(size=(3 * POSES, 1)) * 900.0  # mm/rad, a joint's column
    scale = points.reshape(-1, 1)
    cands = {
        ("joint", 2): joint,
        ("scale", None): scale,
        ("rigid", None): drift.rigid_columns(points),
    }
    var = 0.005**2
    noise = rng.normal(scale=0.005, size=3 * POSES)
    # a joint's zero: 3 mdeg
    found = drift.explain((joint[:, 0] * np.deg2rad(0.003) + noise).reshape(-1, 3), var, cands)
    assert [(e.kind, e.joint) for e in found] == [("joint", 2)]
    assert abs(np.degrees(found[0].values[0]) - 0.003) < 0.0005
    # a rigid motion: no single column explains it, the six of the rigid body do
    rigid = drift.rigid_columns(points) @ np.array([1e-4, -2e-4, 5e-5, 0.05, -0.03, 0.02])
    found = drift.explain((rigid + noise).reshape(-1, 3), var, cands)
    assert [e.kind for e in found] == ["rigid"]
    # scatter alone: already explained by the simplest candidates, none named alone
    found = drift.explain(noise.reshape(-1, 3), var, cands)
    assert len(found) >= 2
    # what no candidate explains
    odd = rng.normal(scale=0.1, size=3 * POSES)
    assert drift.explain(odd.reshape(-1, 3), var, cands) == []


def test_level_judges_pose_means_against_the_expected_error():
    rng = np.random.default_rng(3)
    pose = np.repeat(np.arange(POSES), 3)
    fine = rng.normal(scale=0.02 / np.sqrt(3.0), size=(POSES * 3, 3))
    assert drift.level(fine, pose, 0.02).verdict == "ok"
    far = fine + 0.1
    lvl = drift.level(far, pose, 0.02)
    assert lvl.verdict == "recalibrate" and lvl.rms_mm > 0.15 and lvl.max_mm >= lvl.rms_mm


def test_level_limits_are_where_the_level_changes_its_verdict():
    # one reading a pose: its error is the pose's mean, so the RMS is the one the limits bound
    rng = np.random.default_rng(3)
    pose = np.arange(POSES)
    direction = rng.normal(size=(POSES, 3))
    direction /= np.sqrt(np.mean(np.sum(direction**2, axis=1)))  # RMS 1 mm
    watch, recalibrate = drift.level_limits(0.02, POSES)
    assert 0.02 < watch < recalibrate
    for limit, below, above in ((watch, "ok", "watch"), (recalibrate, "watch", "recalibrate")):
        assert drift.level(direction * limit * 0.999, pose, 0.02).verdict == below
        assert drift.level(direction * limit * 1.001, pose, 0.02).verdict == above


def _six_poses(rng):
    """Six check poses' points (mm) around a base at the origin, and joint 1's column there."""
    ang, rad = rng.uniform(-np.pi, np.pi, 6), rng.uniform(800, 2200, 6)
    pts = np.stack([rad * np.cos(ang), rad * np.sin(ang), rng.uniform(-500, 1500, 6)], axis=1)
    return pts, np.cross([0.0, 0.0, 1.0], pts).reshape(-1, 1)


def test_a_shifted_tracker_is_not_named_joint_1s_zero():
    """Joint 1's zero is a rigid turn about axis 1: one column inside the rigid body's six. A
    tracker shifted 0.03 mm (two checks' scatter 0.013 mm a coordinate), six poses: the one
    column often left scatter-sized residuals and was named ('recalibrate joint 1's offset'):
    68 of 200 draws. The rigid body is named where it fits significantly better (F test at
    NESTED_P): 21 of 200; a true joint-1 slip of 1 mdeg stays joint 1 (199 of 200)."""
    sigma = 0.0092 * np.sqrt(2.0)
    named = {"shift": [], "slip": []}
    for seed in range(200):
        rng = np.random.default_rng(seed)
        pts, j1 = _six_poses(rng)
        cands = {("joint", 1): j1, ("rigid", None): drift.rigid_columns(pts)}
        noise = rng.normal(scale=sigma, size=(6, 3))
        for case, d in (
            ("shift", np.array([0.03, 0.0, 0.0]) + noise),
            ("slip", (j1[:, 0] * np.radians(0.001)).reshape(-1, 3) + noise),
        ):
            found = drift.explain(d, sigma**2, cands)
            named[case].append(found[0].kind if len(found) == 1 else "unsure")
    assert named["shift"].count("joint") <= 30, named["shift"].count("joint")
    assert named["slip"].count("joint") >= 195, named["slip"].count("joint")
