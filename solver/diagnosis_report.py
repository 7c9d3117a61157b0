"""The diagnosis report (FORMATS.md section 5) and the data of its figures, in edge units."""

from __future__ import annotations

import numpy as np

from .effects import Extension, joint_basis, joint_offsets, point_shift, prepare
from .extended import predict_extended
from .kinematics import predict_rows


def parameters(ext: Extension, basis: np.ndarray | None) -> dict:
    """An extension's fitted parameters in mm, degrees, ppm and seconds."""
    c = np.asarray(ext.coef, dtype=float)
    if ext.name == "joint_periodic":
        return {"amplitude_deg": float(np.degrees(np.hypot(c[0], c[1]))),
                "phase_deg": float(np.degrees(np.arctan2(c[1], c[0]))),
                "harmonic": ext.harmonic}
    if ext.name == "joint_scale":
        return {"scale_ppm": float(c[0] * 1e6)}
    if ext.name == "joint_compliance":
        dq = basis @ c
        dq = dq - dq.mean()  # the constant part is the joint's offset
        return {"deflection_rms_deg": float(np.degrees(np.sqrt(np.mean(dq * dq)))),
                "deflection_range_deg": float(np.degrees(dq.max() - dq.min())),
                "gravity_terms": int(len(c))}
    if ext.name == "thermal_drift":
        unit = "ppm_per_c" if ext.variable == "temp_c" else "ppm_per_hour"
        scale = 1e6 if ext.variable == "temp_c" else 1e6 * 3600.0
        return {f"growth_{unit}": float(c[0] * scale), "variable": ext.variable,
                "reference": ext.t_ref}
    if ext.name == "base_shift":
        return {"at_s": ext.at_s, "translation_mm": np.round(c[:3], 5).tolist(),
                "rotation_deg": np.round(np.degrees(c[3:]), 6).tolist(),
                "shift_mm": float(np.linalg.norm(c[:3]))}
    return {}


def evidence(ext: Extension, p: dict, before: float, after: float, decision: dict, m: int) -> str:
    """One sentence a person can check against the figure."""
    gain = (f"modelling it cuts the held-out RMS from {before:.4f} to {after:.4f} mm over {m} poses "
            f"(p = {decision['p_value']:.4f} against this campaign's own null, "
            f"{decision['candidates']} candidates tried)")
    j = None if ext.joint is None else ext.joint + 1
    if ext.name == "joint_periodic":
        return (f"Joint {j}'s residual rotation follows {p['amplitude_deg'] * 1000:.1f} mdeg x "
                f"sin({ext.harmonic} q{j} {p['phase_deg']:+.0f} deg); {gain}.")
    if ext.name == "joint_scale":
        return (f"Joint {j}'s residual rotation grows linearly with its angle, "
                f"{p['scale_ppm']:.0f} ppm; {gain}.")
    if ext.name == "joint_compliance":
        return (f"Joint {j}'s residual rotation follows the gravity torque it carries "
                f"({p['deflection_range_deg'] * 1000:.1f} mdeg peak to peak over the poses); {gain}.")
    if ext.name == "thermal_drift":
        key = [k for k in p if k.startswith("growth_")][0]
        unit = "ppm per degC" if ext.variable == "temp_c" else "ppm per hour"
        return f"SMR distances from the robot base grow {p[key]:.1f} {unit} with {ext.variable}; {gain}."
    if ext.name == "base_shift":
        return (f"Readings after t = {ext.at_s:.0f} s are displaced by {p['shift_mm']:.3f} mm "
                f"as a rigid body; {gain}.")
    return gain


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
        if fitted.name == "joint_periodic":
            e["harmonic"] = fitted.harmonic
        if fitted.name == "base_shift":
            e["at_s"] = fitted.at_s
        e.update(evidence=evidence(fitted, p, before.rmse, after.rmse, decision, m),
                 holdout_rmse_before_mm=before.rmse, holdout_rmse_after_mm=after.rmse,
                 holdout_max_before_mm=before.maxerr, holdout_max_after_mm=after.maxerr,
                 holdout_gain_interval_mm=list(decision["holdout_gain_interval_mm"]),
                 significance={k: decision[k] for k in ("z", "threshold", "p_value")},
                 alternatives=decision["alternatives"], parameters=p)
        effects.append(e)
    effects.sort(key=lambda e: e["holdout_rmse_after_mm"] - e["holdout_rmse_before_mm"])
    return params, {
        "schema": 1,
        "noise_floor_mm": floor,
        "baseline": {"model": "geometric", "holdout_rmse_mm": base.rmse, "holdout_max_mm": base.maxerr},
        "effects": effects,
        "final": {"model": _label(exts), "holdout_rmse_mm": final.rmse, "holdout_max_mm": final.maxerr},
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
    Q, _ = np.linalg.qr(Jt.reshape(len(idx), -1).T)
    meas = prob.meas[mask]
    r_after = predict_extended(layout, x, exts, inputs, bases)[mask] - meas
    out = []
    for i, ext in enumerate(exts):
        if ext.is_joint:
            D = Jq[ext.joint] * (bases[i] @ ext.coef)[pose][:, None]
        else:
            D, _ = point_shift(ext, bases[i][mask], p, _point_origin(ext, layout, x))
        D_res = D - (Q @ (Q.T @ D.ravel())).reshape(D.shape)
        others = [e for j, e in enumerate(exts) if j != i]
        xb, eb, _ = fit_extended(prob, inputs, diag.x0, diag.free, others)
        r_before = predict_extended(layout, xb, eb, inputs)[mask] - meas
        sig = _signature(ext, Jq, p, layout, x, pose, m)
        series = {"name": ext.name, "label": ext.label(), "before": sig(r_before),
                  "after": sig(r_after), "expected": sig(-D_res)}
        if ext.name == "joint_compliance":
            series.update(x=series["expected"], x_label="unabsorbed gravity deflection / mdeg",
                          y_label=f"joint {ext.joint + 1} error / mdeg")
        elif ext.is_joint:
            series.update(x=np.degrees(inputs.q[:, ext.joint]), x_label=f"q{ext.joint + 1} / deg",
                          y_label=f"joint {ext.joint + 1} error / mdeg")
        elif ext.name == "thermal_drift":
            var = inputs.temp_c if ext.variable == "temp_c" else inputs.time_s
            series.update(x=np.nanmean(var, axis=1), y_label="radial growth / ppm",
                          x_label="air temperature / degC" if ext.variable == "temp_c" else "time / s")
        else:
            series.update(x=np.nanmean(inputs.time_s, axis=1), x_label="time / s",
                          y_label="displacement along the shift / mm")
        out.append({k: np.asarray(v, dtype=float) if k in ("x", "before", "after", "expected")
                    else v for k, v in series.items()})
    return out


def _point_origin(ext, layout, x):
    return layout.base(x)[:3, 3] if ext.name == "thermal_drift" else ext.origin


def _signature(ext, Jq, p, layout, x, pose, m):
    """Per pose, the effect's own coordinate of a residual field r (N, 3): joint error in mdeg,
    radial growth in ppm, or displacement along the shift in mm (positive: what the model misses)."""
    if ext.is_joint:
        g = Jq[ext.joint]
        scale = np.degrees(1.0) * 1000.0
    elif ext.name == "thermal_drift":
        g = p - layout.base(x)[:3, 3]
        scale = 1e6
    else:
        u = ext.coef[:3] / max(np.linalg.norm(ext.coef[:3]), 1e-12)
        g = np.broadcast_to(u, p.shape)
        scale = 1.0

    def sig(r):
        num = np.bincount(pose, np.einsum("nc,nc->n", g, r), minlength=m)
        den = np.bincount(pose, np.einsum("nc,nc->n", g, g), minlength=m)
        return -scale * num / np.where(den > 0, den, np.nan)
    return sig
