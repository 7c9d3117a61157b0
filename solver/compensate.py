"""Compensation: joint commands for which a calibrated model puts the SMRs where they are wanted.

Damped least squares (Levenberg-Marquardt) on the joints, every pose at once: one walk of the
chain per iteration gives all poses' SMR centres and joint Jacobians, and each pose takes its own
damped step, clamped to the joint limits. The residual is the full model's (geometry plus every
extension, evaluated at the current joints: compliance under the gravity torques of those
joints, periodic and scale terms, backlash with the approach direction from the previous pose in
visit order, thermal growth at the given temperature); the step uses the geometric joint
Jacobian only. Extensions move joints by millidegrees, so the step's Jacobian is off by parts
in ten thousand: Newton then converges a little more slowly, to the same exact solution. A joint
on its limit that the step would push through is held on it, the step taken by the others.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import configuration
from .effects import Extension, Inputs, joint_offsets, point_shift, prepare
from .kinematics import Layout, predict_rows
from .robot import Robot

STEP_TOL_RAD = 1e-10  # a pose has converged once its step is below this (1e-7 mm per metre)
SAME_ERROR_MM = 1e-4  # seeds' solutions this close in error (mm RMS) reach the target alike
SEED_GRID = 4  # joints 2 and 3 each start from this many values in a configuration's search
# a start's own configuration is kept where its solution misses by no more than this beyond
# the other side's
KEEP_SLACK_MM = 0.005
BOUNDARY_GRID = 721  # where no start lands in its configuration: a joint's range scanned so
BISECTIONS = 40  # then its edge found to within range / 2^40
# the far side's range ends this far (rad) inside the edge: at the edge itself the side's test
# is zero to rounding, and a solution held there reads as either configuration
EDGE_MARGIN_RAD = 1e-7


@dataclass
class Model:
    """A calibrated model as the compensation needs it: its layout and parameters, extensions,
    and the nominal robot the extensions' bases are evaluated on (as model.json's predictions)."""

    layout: Layout
    x: np.ndarray
    extensions: list[Extension]
    nominal: Robot

    def _basis_layout(self) -> tuple[Layout, np.ndarray]:
        lay = Layout(self.nominal, np.eye(4), self.layout.target_names)
        return lay, lay.initial(np.zeros((len(self.layout.target_names), 3)))

    def evaluate(self, q, time_s=None, temp_c=None, prev_q=None):
        """SMR centres (m, K, 3) at joints q (m, n) rad and their joint Jacobian (m, K, 3, n).

        time_s and temp_c are per reading (m, K) or None; the backlash's approach direction
        comes from prev_q (m, n) rad, the joints the arm comes from (NaN rows: not given), else
        from the poses as visited in time_s order, else in row order.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        m, K = q.shape[0], len(self.layout.target_names)
        dq = None
        shifts = []
        if self.extensions:
            inputs = Inputs(q, time_s, temp_c, prev_q=prev_q)
            blay, bx = self._basis_layout()
            bases = [prepare(e, blay, bx, inputs) for e in self.extensions]
            dq = joint_offsets(self.extensions, bases, q.shape[1])
            shifts = [(e, B) for e, B in zip(self.extensions, bases) if not e.is_joint]
        mask = np.ones((m, K), dtype=bool)
        p, _, Jq = predict_rows(self.layout, self.x, q, mask, [], dq, joint_cols=True)
        moved = np.zeros_like(p)
        for ext, B in shifts:
            d, _ = point_shift(ext, B.ravel(), p, ext.kind.origin(ext, self.layout, self.x))
            moved += d
        J = np.moveaxis(Jq.reshape(q.shape[1], m, K, 3), 0, -1)
        return (p + moved).reshape(m, K, 3), J

    def predict(self, q, time_s=None, temp_c=None, prev_q=None) -> np.ndarray:
        return self.evaluate(q, time_s, temp_c, prev_q)[0]


@dataclass
class Compensation:
    """Per pose: joints (m, n) rad, the model's remaining RMS miss over its SMRs (mm), whether
    the iteration converged, and the iterations run."""

    q: np.ndarray
    error_mm: np.ndarray
    converged: np.ndarray
    iterations: int


def _cost(p, desired, w):
    r = (p - desired) * w[..., None]
    return r, np.sum(r * r, axis=(1, 2))


def solve(
    model: Model,
    desired,
    mask,
    q0,
    lower,
    upper,
    time_s=None,
    temp_c=None,
    max_iter: int = 100,
    prev_q=None,
) -> Compensation:
    """Joints from the starts q0 (m, n) rad that put the model's SMRs on desired (m, K, 3) mm
    where mask (m, K) is set, within [lower, upper]; least squares per pose, all poses at once."""
    desired = np.where(mask[..., None], np.asarray(desired, dtype=float), 0.0)
    w = np.asarray(mask, dtype=float)
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    q = np.clip(np.array(q0, dtype=float), lower, upper)
    m, n = q.shape
    p, J = model.evaluate(q, time_s, temp_c, prev_q)
    r, cost = _cost(p, desired, w)
    mu = np.full(m, 1e-3)
    done = np.zeros(m, dtype=bool)
    eye = np.eye(n)
    iterations = 0
    # without extensions each pose is its own problem: only those still iterating are walked
    # (the configuration search's 16 starts a pose, most of them done long before the last);
    # an extension's basis may couple poses (the backlash's visit order), so all are walked
    alone = not model.extensions
    every = np.arange(m)
    while iterations < max_iter and not done.all():
        iterations += 1
        a = np.flatnonzero(~done) if alone else every
        qa, lo_a, hi_a, wa = q[a], lower[a], upper[a], w[a]
        Jw = (J[a] * wa[..., None, None]).reshape(len(a), -1, n)
        A = np.einsum("mri,mrj->mij", Jw, Jw)
        g = np.einsum("mri,mr->mi", Jw, r[a].reshape(len(a), -1))
        scale = np.trace(A, axis1=1, axis2=2)[:, None, None] / n + 1e-12
        # a joint on its limit that the descent would push through is held there and the step
        # solved over the others (the bound's active set): a pose whose best joints lie on a
        # limit then meets the step test, where the clipped full step pushed at the bound,
        # never shrank, and kept every pose of the batch iterating to max_iter
        held = ((qa <= lo_a) & (g > 0.0)) | ((qa >= hi_a) & (g < 0.0))
        if held.any():
            free = ~held
            A = A * (free[:, :, None] & free[:, None, :]) + held[:, :, None] * eye
            g = np.where(held, 0.0, g)
        step = -np.linalg.solve(A + (mu[a, None, None] * scale) * eye, g[..., None])[..., 0]
        step[done[a]] = 0.0
        trial = np.clip(qa + step, lo_a, hi_a)
        if alone:  # the inputs only extensions need
            p_t, J_t = model.evaluate(trial)
        else:
            p_t, J_t = model.evaluate(trial, time_s, temp_c, prev_q)
        r_t, cost_t = _cost(p_t, desired[a], wa)
        better = (cost_t <= cost[a]) & ~done[a]
        b = a[better]
        q[b], r[b], cost[b], J[b] = trial[better], r_t[better], cost_t[better], J_t[better]
        mu[a] = np.where(better, np.maximum(mu[a] * 0.3, 1e-12), np.minimum(mu[a] * 10.0, 1e12))
        small = np.max(np.abs(step), axis=1) < STEP_TOL_RAD
        done[a] |= (better & small) | (~better & (mu[a] >= 1e12)) | (cost[a] < 1e-24)
    # the backlash couples poses: report the miss of the joints as they stand, all together
    p, _ = model.evaluate(q, time_s, temp_c, prev_q)
    r, cost = _cost(p, desired, w)
    count = np.maximum(w.sum(axis=1), 1.0)
    return Compensation(q, np.sqrt(cost / count), done, iterations)


def compensate(
    model: Model,
    desired,
    mask,
    q0=None,
    time_s=None,
    temp_c=None,
    max_iter: int = 100,
    cf=None,
    prev_q=None,
) -> Compensation:
    """Joint commands (rad) for which the model puts its SMRs on desired (m, K, 3) where mask
    (m, K) is set, within the robot's limits.

    q0 (m, n) rad is each pose's starting guess, which keeps the arm's configuration; a pose
    without one (a row of NaN) needs its ABB confdata in cf (m, 4) (cf1, cf4, cf6, cfx; NaN where
    a guess is given): its joints are then solved in that configuration only, and a pose with no
    solution there keeps NaN joints and an infinite error. ValueError for a pose with neither:
    joints are never chosen in a configuration nobody asked for. time_s and temp_c are per
    reading (m, K) or None, as the model's extensions need them; prev_q (m, n) rad the joints
    the arm comes from (NaN rows: not given; the backlash's approach).
    """
    desired = np.asarray(desired, dtype=float)
    mask = np.asarray(mask, dtype=bool)
    robot = model.layout.robot
    m, n = desired.shape[0], robot.n_joints
    q = np.full((m, n), np.nan) if q0 is None else np.array(q0, dtype=float)
    guess = np.all(np.isfinite(q), axis=1)
    lower = np.repeat(robot.lower[None], m, axis=0)
    upper = np.repeat(robot.upper[None], m, axis=0)
    if not guess.all():
        given = np.zeros(m, dtype=bool) if cf is None else np.all(np.isfinite(cf), axis=1)
        lost = ~guess & ~given
        if lost.any():
            raise ValueError(
                f"pose {int(np.flatnonzero(lost)[0]) + 1} has neither starting joints nor a "
                "configuration (cf1, cf4, cf6, cfx)"
            )
        want = np.asarray(cf, dtype=float)[~guess].astype(int)
        found, lo, hi = _in_configuration(model, desired[~guess], mask[~guess], want, max_iter)
        q[~guess], lower[~guess], upper[~guess] = found, lo, hi
    none = ~np.all(np.isfinite(q), axis=1)
    start = np.where(none[:, None], 0.5 * (lower + upper), q)
    res = solve(model, desired, mask, start, lower, upper, time_s, temp_c, max_iter, prev_q)
    if _kept_configuration(model, desired, mask, guess & ~none, q, res, lower, upper, max_iter):
        # some poses solved again on their starting joints' side (all together: the backlash
        # couples consecutive poses)
        res = solve(model, desired, mask, res.q, lower, upper, time_s, temp_c, max_iter, prev_q)
    if not guess.all():
        # the ranges bound joints 1, 4, 5 and 6 only: a pose asked by confdata whose full-model
        # solve crossed a wrist centre's edge has no solution in it (never joints in another)
        asked = ~guess & ~none
        got = configuration.confdata(model.nominal, np.where(asked[:, None], res.q, 0.0))
        none |= asked & np.any(got != np.where(asked[:, None], np.nan_to_num(cf), 0), axis=1)
    res.q[none] = np.nan
    res.error_mm[none] = np.inf
    res.converged[none] = False
    return res


def _kept_configuration(model: Model, desired, mask, guess, q0, res, lower, upper, max_iter):
    """Where a pose's solution left its starting joints' configuration (a start by an edge, the
    elbow nearly stretched: the damped steps fell to the mirror solution, degrees away), its
    joints and ranges set (in place) to the solution on the start's side; whether any was."""
    robot = model.nominal
    if not guess.any() or not configuration.supports(robot):
        return False
    want = configuration.confdata(robot, np.where(guess[:, None], q0, 0.0))
    got = configuration.confdata(robot, np.where(guess[:, None], res.q, 0.0))
    geo = Model(model.layout, model.x, [], robot)
    moved = False
    for i in np.flatnonzero(guess & np.any(want != got, axis=1)):
        found = _across_boundary(
            geo, desired[i], mask[i], want[i], res.q[i], lower[i], upper[i], max_iter
        )
        # kept where it reaches the targets as well and lies no further from the start (a
        # start across the edge from every solution, or by the wrist's singularity, keeps the
        # nearer solution and its warning)
        if (
            found is not None
            and found[1] <= res.error_mm[i] + KEEP_SLACK_MM
            and np.max(np.abs(found[0] - q0[i])) <= np.max(np.abs(res.q[i] - q0[i]))
        ):
            res.q[i], _, lower[i], upper[i] = found
            moved = True
    return moved


def _seeds(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Starting joints (m, S, 6) within each pose's configuration's ranges: joints 1, 4 and 6
    mid-range, joints 2 and 3 on a grid (the wrist centre's sides are what the grid tries), and
    joint 5 in the middle of each half turn of its side (one, unless its limits pass 180 deg).

    Joint 5 is singular at 0 and 180 deg: the middle of a side of +-360 deg limits is the
    singularity, and from there a real UR5's own measured pose came out 'unreachable' in its own
    configuration; the middles of its two half turns (90 and 270 deg) are the wrist's two flips
    on that side."""
    m = len(lo)
    halves = max(1, int(np.ceil(np.max(hi[:, 4] - lo[:, 4]) / np.pi - 1e-9)))
    mid = 0.5 * (lo + hi)
    grid = np.linspace(0.15, 0.85, SEED_GRID)
    s2 = lo[:, None, 1] + grid[None] * (hi - lo)[:, None, 1]
    s3 = lo[:, None, 2] + grid[None] * (hi - lo)[:, None, 2]
    # per pose, the middles of joint 5's side cut into `halves` equal parts (of at most 180 deg
    # where its range is that wide; one part, its middle, where the range is within 180 deg)
    parts = np.maximum(1, np.ceil((hi[:, 4] - lo[:, 4]) / np.pi - 1e-9))  # (m,)
    k = np.minimum(np.arange(halves)[None], parts[:, None] - 1)  # (m, halves)
    s5 = lo[:, None, 4] + (k + 0.5) * ((hi - lo)[:, 4] / parts)[:, None]
    per = SEED_GRID * SEED_GRID
    out = np.repeat(mid[:, None], halves * per, axis=1)
    out[:, :, 1] = np.tile(np.repeat(s2, SEED_GRID, axis=1), (1, halves))
    out[:, :, 2] = np.tile(s3, (1, SEED_GRID * halves))
    out[:, :, 4] = np.repeat(s5, per, axis=1)
    return out.reshape(m, halves * per, -1)


def least_wound(q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """q (m, n) rad with each joint turned by whole turns to its angle nearest zero within
    [lo, hi]: the same pose of the arm (every joint revolute), in the same confdata (joints 1, 4
    and 6 are bound to their quadrants, joint 5 to its side)."""
    turns = np.arange(-2, 3)[:, None, None] * 2 * np.pi
    alt = q[None] + turns  # (5, m, n)
    ok = (alt >= lo[None]) & (alt <= hi[None])
    pick = np.argmin(np.where(ok, np.abs(alt), np.inf), axis=0)
    out = np.take_along_axis(alt, pick[None], axis=0)[0]
    return np.where(np.isfinite(q), out, q)


def _across_boundary(geo: Model, desired, mask, cf, q, lo, hi, max_iter):
    """The solution in configuration cf (4,) nearest a solution q (n,) rad in another one, where
    the configuration's edge is a joint's angle (joint 3 for the lower-arm side, else joint 2):
    solved from just across that edge with the joint held on its far side. (joints, error mm,
    the joint ranges that keep it there), or None.
    Near the edge both sides' solutions attract the damped steps to the nearer one, so every
    start of the search lands on the wrong side."""
    robot = geo.nominal
    for j in (2, 1):
        grid = np.linspace(lo[j], hi[j], BOUNDARY_GRID)
        trial = np.repeat(q[None], len(grid), axis=0)
        trial[:, j] = grid
        inside = np.all(configuration.confdata(robot, trial) == cf, axis=1)
        if not inside.any():
            continue
        k = int(np.flatnonzero(inside)[np.argmin(np.abs(grid[inside] - q[j]))])
        a, b = q[j], grid[k]  # a outside, b inside: the edge between them by bisection
        for _ in range(BISECTIONS):
            trial = q.copy()
            trial[j] = 0.5 * (a + b)
            if np.all(configuration.confdata(robot, trial[None])[0] == cf):
                b = trial[j]
            else:
                a = trial[j]
        # the far side's run of grid points from b on, as the joint's range
        step = 1 if grid[k] >= q[j] else -1
        end = k
        while 0 <= end + step < len(grid) and inside[end + step]:
            end += step
        inner = b + step * min(EDGE_MARGIN_RAD, 0.5 * abs(grid[end] - b))
        lo_j, hi_j = sorted((inner, grid[end]))
        low, high = lo.copy(), hi.copy()
        low[j], high[j] = lo_j, hi_j
        start = q.copy()
        # the mirror of q across the edge: where the far side's solution lies when the edge is
        # a singularity (the stretched elbow), at which the joint's own gradient vanishes
        start[j] = np.clip(2.0 * b - q[j], lo_j, hi_j)
        res = solve(
            geo, desired[None], mask[None], start[None], low[None], high[None], max_iter=max_iter
        )
        if np.all(configuration.confdata(robot, res.q)[0] == cf):
            return res.q[0], float(res.error_mm[0]), low, high
    return None


def _in_configuration(model: Model, desired, mask, cf, max_iter):
    """Per pose, the geometric model's best joints in configuration cf (m, 4) (NaN where none
    reaches the target there), and the joint ranges the configuration allows (m, n) rad."""
    robot = model.nominal
    if not configuration.supports(robot):
        raise ValueError(
            f"a configuration (cf1, cf4, cf6, cfx) describes a six-axis arm; {robot.name} has "
            f"{robot.n_joints} joints: give starting joints"
        )
    lo, hi = configuration.bounds(robot, cf)
    geo = Model(model.layout, model.x, [], model.nominal)
    s = _seeds(lo, hi)
    m, S, n = s.shape
    res = solve(
        geo,
        np.repeat(desired, S, axis=0),
        np.repeat(mask, S, axis=0),
        s.reshape(m * S, n),
        np.repeat(lo, S, axis=0),
        np.repeat(hi, S, axis=0),
        max_iter=max_iter,
    )
    got = configuration.confdata(robot, res.q).reshape(m, S, 4)
    err = np.where(np.all(got == cf[:, None], axis=2), res.error_mm.reshape(m, S), np.inf)
    sols = res.q.reshape(m, S, n)
    anywhere = res.error_mm.reshape(m, S)
    for i in np.flatnonzero(err.min(axis=1) > anywhere.min(axis=1) + SAME_ERROR_MM):
        # the starts came closer in another configuration than in this one (or none reached
        # this one): next to a boundary (the elbow stretched) the two sides' solutions are
        # tenths of a degree apart, and the starts in this one stopped in local minima
        nearest = sols[i, int(np.argmin(anywhere[i]))]
        found = _across_boundary(geo, desired[i], mask[i], cf[i], nearest, lo[i], hi[i], max_iter)
        if found is not None and found[1] < err[i].min():  # the final solve keeps to that side
            sols[i, 0], err[i, 0], lo[i], hi[i] = found
    # of the seeds as close as the best (within SAME_ERROR_MM), the least wound joints: a joint
    # of +-360 deg reaches a position a turn either way in the same confdata, which names the
    # turn of joints 1, 4 and 6 only (the first among equals: reproducible)
    close = err <= err.min(axis=1, keepdims=True) + SAME_ERROR_MM
    wound = np.where(close, np.sum(sols * sols, axis=2), np.inf)
    best = np.argmin(wound, axis=1)
    out = least_wound(sols[np.arange(m), best], lo, hi)
    out[~np.isfinite(err[np.arange(m), best])] = np.nan
    return out, lo, hi
