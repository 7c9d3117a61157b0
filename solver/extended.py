"""The geometric model plus extensions: prediction and joint least-squares fit."""

from __future__ import annotations

import numpy as np

from .effects import Extension, Inputs, joint_offsets, point_shift, prepare
from .identify import Problem
from .kinematics import Layout, predict, predict_rows
from .lm import levenberg_marquardt
from .prior import Prior


def _origin(ext: Extension, layout: Layout, x) -> np.ndarray:
    return ext.kind.origin(ext, layout, x)


def predict_extended(layout: Layout, x, exts, inputs: Inputs, bases=None) -> np.ndarray:
    """SMR centres (m, K, 3) predicted by the geometric model with its extensions."""
    bases = bases or [prepare(e, layout, x, inputs) for e in exts]
    dq = joint_offsets(exts, bases, layout.robot.n_joints)
    p = predict(layout, x, inputs.q, dq)
    moved = np.zeros_like(p)
    for ext, B in zip(exts, bases):
        if not ext.is_joint:
            d, _ = point_shift(ext, B.ravel(), p.reshape(-1, 3), _origin(ext, layout, x))
            moved += d.reshape(p.shape)
    return p + moved


def predict_model(nominal_robot, layout: Layout, x, exts, inputs: Inputs) -> np.ndarray:
    """SMR centres (m, K, 3) of a fitted extended model on new poses, its extensions' bases taken
    on the nominal arm as a model file is used (the fitted geometry moves only the prediction)."""
    nominal = Layout(nominal_robot, np.eye(4), layout.target_names)
    nx = nominal.initial(np.zeros((len(layout.target_names), 3)))
    bases = [prepare(e, nominal, nx, inputs) for e in exts]
    return predict_extended(layout, x, exts, inputs, bases)


def extension_rows(layout, x, exts, bases, inputs, mask, idx):
    """Predicted readings (N, 3) and the transposed Jacobian over [x[idx], every coef] (P, N, 3)."""
    dq = joint_offsets(exts, bases, layout.robot.n_joints)
    p, Jt, Jq = predict_rows(layout, x, inputs.q, mask, idx, dq=dq, joint_cols=True)
    pose = np.nonzero(mask)[0]
    blocks, moved = [Jt], np.zeros_like(p)
    for ext, B in zip(exts, bases):
        if ext.is_joint:
            blocks.append(B[pose].T[:, :, None] * Jq[ext.joint][None])
        else:
            d, J = point_shift(ext, B[mask], p, _origin(ext, layout, x))
            moved += d
            blocks.append(J)
    return p + moved, np.concatenate(blocks, axis=0)


def fit_extended(
    prob: Problem,
    inputs: Inputs,
    x0,
    free,
    exts,
    poses=None,
    max_iter=50,
    start=None,
    prior: Prior | None = None,
):
    """Fit free geometric parameters and every extension's coefficients on the given poses.

    Returns (x, exts with fitted coef, LMResult). Bases are evaluated at x0 and held; the fit
    starts from `start` (default x0) and from each extension's coef where it has one. prior: the
    geometric calibration's (solver.prior), its rows after the readings' (the LMResult's cost
    includes them), so that without extensions the fit is ls-sum's.
    """
    poses = np.arange(prob.q.shape[0]) if poses is None else np.asarray(poses)
    sub = inputs.subset(poses)
    meas = prob.meas[poses]
    mask = np.all(np.isfinite(meas), axis=-1)
    y = meas[mask]
    layout = prob.layout
    bases = [prepare(e, layout, x0, sub) for e in exts]
    idx = np.flatnonzero(free)
    sizes = [e.n_params for e in exts]
    x = np.array(x0 if start is None else start, dtype=float)
    z0 = np.concatenate(
        [x[idx]] + [np.zeros(n) if len(e.coef) != n else e.coef for e, n in zip(exts, sizes)]
    )

    def unpack(z):
        xx = x.copy()
        xx[idx] = z[: len(idx)]
        out, k = [], len(idx)
        for e, n in zip(exts, sizes):
            out.append(Extension(**{**e.__dict__, "coef": z[k : k + n]}))
            k += n
        return xx, out

    def fun(z):
        xx, ee = unpack(z)
        p, Jt = extension_rows(layout, xx, ee, bases, sub, mask, idx)
        return (p - y).ravel(), Jt.reshape(Jt.shape[0], -1)

    def residual(z):
        xx, ee = unpack(z)
        return (predict_extended(layout, xx, ee, sub, bases)[mask] - y).ravel()

    if prior is None:
        res = levenberg_marquardt(fun, z0, residual, max_iter=max_iter)
    else:
        res = levenberg_marquardt(None, z0, max_iter=max_iter, **prior.fit(fun, x, idx, residual))
    xx, ee = unpack(res.x)
    return xx, ee, res
