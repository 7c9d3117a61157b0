"""The diagnosis report (FORMATS.md section 5) and the data of its figures, in edge units."""

from __future__ import annotations

import numpy as np

from .effects import Extension, joint_basis, joint_offsets, point_shift, prepare
from .extended import predict_extended
from .finite import finite
from .kinematics import predict_rows


def parameters(ext: Extension, basis: np.ndarray | None) -> dict:
    """An extension's fitted parameters in mm, degrees, ppm and seconds."""
    return ext.kind.parameters(ext, basis)


def evidence(ext: Extension, p: dict, before: float, after: float, decision: dict, m: int) -> str:
    """One sentence a person can check against the figure."""
    gain = (
        f"modelling it cuts the held-out RMS from {before:.4f} to {after:.4f} mm over {m} poses "
        f"(p = {decision['p_value']:.4f} against this campaign's own null, "
        f"{decision['candidates']} candidates tried)"
    )
    return ext.kind.evidence(ext, p, gain)


def _label(exts) -> str:
    return "+".join(["geometric"] + [e.label() for e in exts])


def build_report(diag, steps, base, final, exts, x, floor, n_candidates):
    """Each extension's parameters (in step order) and the report: FORMATS.md section 5, plus what
    a person needs to check it (effects most important first)."""
    layout, inputs = diag.prob.layout, diag.inputs
    m = diag.prob.q.shape[0]
    effects, params = [], []
    for (_, before, after, decision), fitted in zip(steps, exts):
        basis = joint_basis(fitted, layout, diag.x0, inputs) if fitted.is_joint else None
        p = parameters(fitted, basis)
        params.append(p)
        e = {"name": fitted.name}
        if fitted.joint is not None:
            e["joint"] = fitted.joint + 1
        e.update({k: getattr(fitted, k) for k in fitted.kind.report_keys})
        e.update(
            evidence=evidence(fitted, p, before.rmse, after.rmse, decision, m),
            holdout_rmse_before_mm=before.rmse,
            holdout_rmse_after_mm=after.rmse,
            holdout_max_before_mm=before.maxerr,
            holdout_max_after_mm=after.maxerr,
            holdout_gain_interval_mm=list(decision["holdout_gain_interval_mm"]),
            significance={k: decision[k] for k in ("z", "threshold", "p_value")},
            alternatives=decision["alternatives"],
            parameters=p,
        )
        effects.append(e)
    effects.sort(key=lambda e: e["holdout_rmse_after_mm"] - e["holdout_rmse_before_mm"])
    return params, {
        "schema": 1,
        "noise_floor_mm": floor,
        "baseline": {
            "model": "geometric",
            "holdout_rmse_mm": base.rmse,
            "holdout_max_mm": base.maxerr,
        },
        "effects": effects,
        "final": {
            "model": _label(exts),
            "holdout_rmse_mm": final.rmse,
            "holdout_max_mm": final.maxerr,
        },
        "poses": m,
        "readings": int(diag.prob.mask.sum()),
        "candidates_tested": n_candidates,
    }


def figure_series(diag, steps, exts, x) -> list[dict]:
    """For each found effect, its signature in the residuals against its variable, before and after.

    `before` is the residual of the model fitted without the effect, `expected` what the effect
    leaves in such residuals once the geometric parameters have absorbed what they can (its
    displacement minus the projection on the geometric Jacobian): the points should follow it.
    `after` is the residual of the final model.
    """
    from .extended import fit_extended

    prob, inputs, layout = diag.prob, diag.inputs, diag.prob.layout
    mask = prob.mask
    pose = np.nonzero(mask)[0]
    m = prob.q.shape[0]
    bases = [prepare(e, layout, diag.x0, inputs) for e in exts]
    dq = joint_offsets(exts, bases, layout.robot.n_joints)
    idx = np.flatnonzero(diag.free)
    p, Jt, Jq = predict_rows(layout, x, inputs.q, mask, idx, dq=dq, joint_cols=True)
    Q, _ = np.linalg.qr(finite(Jt.reshape(len(idx), -1).T, "an effect's Jacobian"))
    meas = prob.meas[mask]
    r_after = predict_extended(layout, x, exts, inputs, bases)[mask] - meas
    out = []
    for i, ext in enumerate(exts):
        if ext.is_joint:
            D = Jq[ext.joint] * (bases[i] @ ext.coef)[pose][:, None]
        else:
            D, _ = point_shift(ext, bases[i][mask], p, ext.kind.origin(ext, layout, x))
        D_res = D - (Q @ (Q.T @ D.ravel())).reshape(D.shape)
        others = [e for j, e in enumerate(exts) if j != i]
        xb, eb, _ = fit_extended(prob, inputs, diag.x0, diag.free, others)
        r_before = predict_extended(layout, xb, eb, inputs)[mask] - meas
        sig = _signature(ext, Jq, p, layout, x, pose, m)
        series = {
            "name": ext.name,
            "label": ext.label(),
            "before": sig(r_before),
            "after": sig(r_after),
            "expected": sig(-D_res),
        }
        series.update(ext.kind.figure(ext, inputs, series["expected"]))
        out.append(
            {
                k: np.asarray(v, dtype=float) if k in ("x", "before", "after", "expected") else v
                for k, v in series.items()
            }
        )
    return out


def _signature(ext, Jq, p, layout, x, pose, m):
    """Per pose, the effect's own coordinate of a residual field r (N, 3): joint error in mdeg,
    radial growth in ppm, or displacement along the shift in mm (positive: what the model misses)."""
    g, scale = ext.kind.signature_axis(ext, Jq, p, layout, x)

    def sig(r):
        num = np.bincount(pose, np.einsum("nc,nc->n", g, r), minlength=m)
        den = np.bincount(pose, np.einsum("nc,nc->n", g, g), minlength=m)
        return -scale * num / np.where(den > 0, den, np.nan)

    return sig
