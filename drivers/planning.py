"""Campaign planning: valid random poses, an observability-optimal subset, a short order."""

from __future__ import annotations

import numpy as np

from robocal.solver import observability as obs
from robocal.solver.identifiability import structural
from robocal.solver.kinematics import Layout, flange_frames, predict, predict_rows
from robocal.solver.robot import Robot

from .cell import VirtualCell, limit_margin, too_constrained
from .world import ACCEL_S, DEFAULT_SPEEDS_DEG_S


def _targets(targets) -> tuple[tuple[str, ...], np.ndarray]:
    """Names and (K, 3) positions of the SMRs, from a {name: xyz} dict or a (K, 3) array."""
    if isinstance(targets, dict):
        return tuple(targets), np.array(list(targets.values()), dtype=float).reshape(-1, 3)
    t = np.asarray(targets, dtype=float).reshape(-1, 3)
    return tuple(f"T{i + 1}" for i in range(len(t))), t


def _planning_cell(robot: Robot, base_in_tracker, targets, acceptance_deg, floor_mm):
    """A cell whose "true" arm is the model we plan with: its pose_checks are the rules."""
    names, t = _targets(targets)
    return VirtualCell(
        robot,
        robot,
        names,
        t,
        t,
        np.asarray(base_in_tracker, dtype=float),
        acceptance_rad=np.deg2rad(acceptance_deg),
        floor_clearance_mm=floor_mm,
    )


def pose_checks(
    robot: Robot,
    base_in_tracker,
    targets,
    q,
    acceptance_deg: float = 60.0,
    floor_mm: float = 150.0,
    bounds=None,
) -> dict[str, np.ndarray]:
    """Per constraint, which poses (m,) pass: the virtual cell's checks, plus SMRs inside `bounds`.

    bounds: optional ((xmin, ymin, zmin), (xmax, ymax, zmax)), mm in the robot base frame.
    """
    cell = _planning_cell(robot, base_in_tracker, targets, acceptance_deg, floor_mm)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    checks = cell.pose_checks(q)
    if bounds is not None:
        lo, hi = np.asarray(bounds, dtype=float).reshape(2, 3)
        lay = Layout(robot, np.eye(4), cell.target_names)
        p = predict(lay, lay.initial(cell.nominal_targets), q)
        checks["bounds"] = np.all((p >= lo) & (p <= hi), axis=(1, 2))
    return checks


def plan_poses(
    robot: Robot,
    base_in_tracker,
    targets,
    n: int,
    rng,
    acceptance_deg: float = 60.0,
    floor_mm: float = 150.0,
    bounds=None,
    max_batches: int = 50,
) -> np.ndarray:
    """n poses (n, N) rad, uniform within the limits, meeting every check on the nominal model."""
    margin = limit_margin(robot)
    lo, hi = robot.lower + margin, robot.upper - margin
    batch = max(1024, 4 * n)
    found: list[np.ndarray] = []
    passed: dict[str, int] = {}
    count = 0
    for _ in range(max_batches):
        q = rng.uniform(lo, hi, size=(batch, robot.n_joints))
        checks = pose_checks(robot, base_in_tracker, targets, q, acceptance_deg, floor_mm, bounds)
        for name, ok in checks.items():
            passed[name] = passed.get(name, 0) + int(ok.sum())
        found.append(q[np.logical_and.reduce(list(checks.values()))])
        count += len(found[-1])
        if count >= n:
            return np.concatenate(found)[:n]
    cell = _planning_cell(robot, base_in_tracker, targets, acceptance_deg, floor_mm)
    raise too_constrained(n, count, max_batches * batch, passed, cell, q)


def default_speeds(n_joints: int) -> np.ndarray:
    """Joint speeds (rad/s) of the simulated world: IRB 2600-class, 360 deg/s beyond six axes."""
    return np.deg2rad(np.asarray((DEFAULT_SPEEDS_DEG_S + (360.0,) * n_joints)[:n_joints]))


def move_time(q_a, q_b, speeds=None) -> np.ndarray:
    """Seconds from q_a to q_b (broadcasting), as drivers/world.py moves: slowest joint + ramp."""
    q_a, q_b = np.asarray(q_a, dtype=float), np.asarray(q_b, dtype=float)
    v = default_speeds(q_a.shape[-1]) if speeds is None else np.asarray(speeds, dtype=float)
    return np.max(np.abs(q_b - q_a) / v, axis=-1) + ACCEL_S


def total_move_time(q, order=None, start=None, speeds=None) -> float:
    """Seconds to visit the poses q in `order` (default as given), from `start` if given."""
    q = np.asarray(q, dtype=float)
    path = q if order is None else q[np.asarray(order)]
    if start is not None:
        path = np.vstack([np.asarray(start, dtype=float)[None], path])
    return float(np.sum(move_time(path[:-1], path[1:], speeds)))


def _nearest_neighbour(D: np.ndarray, first: int) -> np.ndarray:
    n = len(D)
    path, free = [first], np.ones(n, dtype=bool)
    free[first] = False
    for _ in range(n - 1):
        j = int(np.argmin(np.where(free, D[path[-1]], np.inf)))
        path.append(j)
        free[j] = False
    return np.array(path)


def _path_cost(D: np.ndarray, path: np.ndarray) -> float:
    return float(D[path[:-1], path[1:]].sum())


def _two_opt(D: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Reverse segments path[i..j] (path[0] fixed) while that shortens the open path."""
    # valid because move times between poses are symmetric; only those out of path[0] may not be
    path = path.copy()
    L = len(path)
    improved = True
    while improved:
        improved = False
        for i in range(1, L - 1):
            a, b = path[i - 1], path[i]
            c = path[i + 1 :]  # candidate segment ends j = i+1 .. L-1
            delta = D[a, c] - D[a, b]
            d = path[i + 2 :]  # the pose after each end, none after the last
            delta[:-1] += D[b, d] - D[c[:-1], d]
            j = int(np.argmin(delta))
            if delta[j] < -1e-9:
                path[i : i + j + 2] = path[i : i + j + 2][::-1].copy()
                improved = True
    return path


OR_OPT_SEGMENT = 3  # longest run of poses Or-opt moves elsewhere in the path


def _or_opt(D: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Move runs of up to OR_OPT_SEGMENT poses (either way round) elsewhere in the open path
    (path[0] fixed) while that shortens it; the best move of each pass first."""
    path = path.copy()
    while True:
        best_delta, best = -1e-9, None
        L = len(path)
        for length in range(1, min(OR_OPT_SEGMENT, L - 2) + 1):
            for i in range(1, L - length + 1):
                seg = path[i : i + length]
                a, b = seg[0], seg[-1]
                prev = path[i - 1]
                nxt = path[i + length] if i + length < L else None
                gain = D[prev, a] + (0.0 if nxt is None else D[b, nxt] - D[prev, nxt])
                rest = np.concatenate([path[:i], path[i + length :]])
                lo, hi = rest, np.append(rest[1:], -1)  # insert between lo[j] and hi[j]
                end = hi < 0
                hi_ = np.where(end, 0, hi)
                base = np.where(end, 0.0, D[lo, hi_])
                fwd = D[lo, a] + np.where(end, 0.0, D[b, hi_]) - base
                rev = D[lo, b] + np.where(end, 0.0, D[a, hi_]) - base
                for cost, flip in ((fwd, False), (rev, True)):
                    j = int(np.argmin(cost))
                    delta = cost[j] - gain
                    if delta < best_delta:
                        best_delta, best = delta, (i, length, j, flip)
        if best is None:
            return path
        i, length, j, flip = best
        seg = path[i : i + length][::-1] if best[3] else path[i : i + length]
        rest = np.concatenate([path[:i], path[i + length :]])
        path = np.concatenate([rest[: j + 1], seg, rest[j + 1 :]])


def _local_search(D: np.ndarray, path: np.ndarray) -> np.ndarray:
    """2-opt and Or-opt in turn until neither shortens the open path."""
    cost = np.inf
    while _path_cost(D, path) < cost - 1e-9:
        cost = _path_cost(D, path)
        path = _or_opt(D, _two_opt(D, path))
    return path


# Iterated local search: kicks of the best path (double bridges, out of reach of 2-opt and
# Or-opt) each followed by local search, kept when shorter. A fixed seed keeps the order
# deterministic; the kicks are fewer for long paths, whose local search costs more (~n^2).
KICKS_AT_40 = 60
KICK_SEED = 20240
# no kick cuts the path among its first poses (their short steps from the local search stay,
# unless the search after a kick finds better): the campaign's predictor extrapolates from a few
# readings there, and a longer step misses the capture radius (bench acquire: more searches)
KICK_FROM = 8


def _kicked(D: np.ndarray, path: np.ndarray) -> np.ndarray:
    """The shortest path found from `path` by double-bridge kicks, each with local search."""
    L = len(path)
    if L < KICK_FROM + 3:
        return path
    rng = np.random.default_rng(KICK_SEED)
    kicks = int(KICKS_AT_40 * min(1.0, (40.0 / (L - 1)) ** 2))
    cost = _path_cost(D, path)
    for _ in range(kicks):
        i, j, k = np.sort(rng.choice(np.arange(KICK_FROM, L), size=3, replace=False))
        trial = np.concatenate([path[:i], path[j:k], path[i:j], path[k:]])
        trial = _local_search(D, trial)
        c = _path_cost(D, trial)
        if c < cost - 1e-9:
            path, cost = trial, c
    return path


def order_poses(q, start=None, speeds=None) -> np.ndarray:
    """Deterministic order of q (n, N), never slower than as given: nearest neighbour, then
    2-opt and Or-opt in turn until neither shortens the path, then kicked out of that local
    optimum and searched again (_kicked), on the controller's move time."""
    # The path is open; without a start it may begin at any pose.
    q = np.asarray(q, dtype=float)
    n = len(q)
    if n < 2:
        return np.arange(n)
    # Node 0 is the start; with no start it is a free virtual node (zero-cost first move).
    D = np.zeros((n + 1, n + 1))
    D[1:, 1:] = move_time(q[:, None], q[None], speeds)
    if start is not None:
        D[0, 1:] = move_time(np.asarray(start, dtype=float), q, speeds)
    firsts = [None] if start is not None else range(1, n + 1)
    best = None
    for f in firsts:
        if f is None:
            path = _nearest_neighbour(D, 0)
        else:
            sub = D.copy()
            sub[0, :] = np.inf
            sub[0, f] = 0.0
            path = _nearest_neighbour(sub, 0)
        if best is None or _path_cost(D, path) < _path_cost(D, best):
            best = path
    assert best is not None  # n >= 1 poses: at least one path was built
    best = _kicked(D, _local_search(D, best))
    given = np.arange(n + 1)
    if _path_cost(D, given) <= _path_cost(D, best):
        best = given
    return best[1:] - 1


def candidate_jacobians(robot: Robot, base_in_tracker, targets, q) -> obs.PoseJacobians:
    """Per pose, the nominal ls-sum identification Jacobian on the free parameters, without
    the zeros of each SMR's rows in the other SMRs' coordinates (memory linear in the SMRs)."""
    # free parameters as calibrate() picks them, so the design is for what will be identified
    names, t = _targets(targets)
    lay = Layout(robot, np.asarray(base_in_tracker, dtype=float), names)
    x = lay.initial(t)
    free = structural(lay, x, np.ones(lay.n_params, dtype=bool)).free
    ts = lay.target_slice
    shared = np.flatnonzero(free[: ts.start])  # geometry and base: every reading moves with them
    q = np.atleast_2d(np.asarray(q, dtype=float))
    m, K = len(q), len(names)
    _, Jt = predict_rows(lay, x, q, np.ones((m, K), dtype=bool), shared)
    own_free = free[ts].reshape(K, 3)
    # an SMR's point moves with its own coordinates (flange frame) through the flange rotation
    R = flange_frames(lay, x, q)[0]
    return obs.PoseJacobians(
        Jt.reshape(len(shared), m, K, 3).transpose(1, 2, 3, 0),
        R[:, None, :, :] * own_free[None, :, None, :],
        own_free,
    )


def plan_campaign(
    robot: Robot,
    base_in_tracker,
    targets,
    n_candidates: int,
    rng,
    k=None,
    criterion: str = "D",
    start=None,
    speeds=None,
    acceptance_deg: float = 60.0,
    floor_mm: float = 150.0,
    bounds=None,
    order: bool = True,
    progress=None,
) -> tuple[np.ndarray, dict]:
    """Valid random candidates -> optionally the k best by `criterion` -> ordered (unless not
    asked: the paper measures in plan order); (q, summary). progress(fraction in 0..1), if
    given, is called as the planning advances (mostly the D-optimal exchange)."""
    # The summary compares move time in candidate order with the planned order, and the chosen
    # poses' observability with the first k candidates (a random choice of the same size).
    # Shares of the work: drawing candidates and their Jacobians, the choice, the ordering.
    step = progress or (lambda fraction: None)
    cand = plan_poses(
        robot, base_in_tracker, targets, n_candidates, rng, acceptance_deg, floor_mm, bounds
    )
    step(0.05)
    J = obs.unit_columns(candidate_jacobians(robot, base_in_tracker, targets, cand))
    step(0.1)
    if k is None:
        chosen = np.arange(n_candidates)
        random_ = chosen
    else:
        chosen = obs.select_poses(J, k, criterion, progress=lambda f: step(0.1 + 0.8 * f))
        random_ = np.arange(k)  # candidates are i.i.d. random, so any k of them are a random choice
    step(0.9)
    perm = order_poses(cand[chosen], start, speeds) if order else np.arange(len(chosen))
    step(0.95)
    q = cand[chosen][perm]
    summary = {
        "n_candidates": n_candidates,
        "n_poses": len(q),
        "criterion": criterion if k is not None else None,
        "move_time_s": {
            "before": total_move_time(cand[chosen], None, start, speeds),
            "after": total_move_time(q, None, start, speeds),
        },
        "observability": {
            "random": obs.observability_indices(J[random_]),
            "chosen": obs.observability_indices(J[chosen]),
        },
    }
    return q, summary
