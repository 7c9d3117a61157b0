"""The diagnosis report (FORMATS.md section 5) and the data of its figures, in edge units."""

from __future__ import annotations

import numpy as np

from .effects import Extension, Inputs, joint_basis, prepare
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


def evidence(ext: Extension, p: dict, before: float, after: float, t: float, m: int) -> str:
    """One sentence a person can check against the figure."""
    gain = f"modelling it cuts the held-out RMS from {before:.4f} to {after:.4f} mm (paired t = {t:.1f} over {m} poses)"
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
    for (ext, before, after, t), fitted in zip(steps, exts):
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
        e.update(evidence=evidence(fitted, p, before.rmse, after.rmse, t, m),
                 holdout_rmse_before_mm=before.rmse, holdout_rmse_after_mm=after.rmse,
                 holdout_max_before_mm=before.maxerr, holdout_max_after_mm=after.maxerr,
                 paired_t=t, parameters=p)
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


def _joint_error(layout, x, exts, inputs, meas, joint):
    """Per pose, the joint-angle error that best explains its residuals (rad; NaN if unseen)."""
    mask = np.all(np.isfinite(meas), axis=-1)
    r = predict_extended(layout, x, exts, inputs)[mask] - meas[mask]
    _, _, Jq = predict_rows(layout, x, inputs.q, mask, [], joint_cols=True)
    g = Jq[joint]
    pose = np.nonzero(mask)[0]
    num = np.bincount(pose, np.einsum("nc,nc->n", g, r), minlength=len(inputs.q))
    den = np.bincount(pose, np.einsum("nc,nc->n", g, g), minlength=len(inputs.q))
    # pred - meas = -(missing joint error) along the joint's motion
    return -num / np.where(den > 0, den, np.nan)


def figure_series(diag, steps, exts, x) -> list[dict]:
    """For each found effect, its signature in the residuals against its variable, before and after."""
    from .extended import fit_extended

    prob, inputs, layout = diag.prob, diag.inputs, diag.prob.layout
    out = []
    for i, ext in enumerate(exts):
        others = [e for j, e in enumerate(exts) if j != i]
        xb, eb, _ = fit_extended(prob, inputs, diag.x0, diag.free, others)
        series = {"name": ext.name, "label": ext.label()}
        if ext.is_joint:
            j = ext.joint
            before = _joint_error(layout, xb, eb, inputs, prob.meas, j)
            after = _joint_error(layout, x, exts, inputs, prob.meas, j)
            model = joint_basis(ext, layout, diag.x0, inputs) @ ext.coef
            if ext.name == "joint_compliance":
                var, xl = np.degrees(model - model.mean()) * 1000, "fitted gravity deflection / mdeg"
            else:
                var, xl = np.degrees(inputs.q[:, j]), f"q{j + 1} / deg"
            shift = np.nanmean(before - model)  # joint offsets absorb the constant part
            series.update(x=var, before=np.degrees(before - shift) * 1000,
                          after=np.degrees(after) * 1000, model_x=var,
                          model_y=np.degrees(model - np.mean(model)) * 1000 if
                          ext.name == "joint_compliance" else np.degrees(model) * 1000,
                          x_label=xl, y_label=f"joint {j + 1} error / mdeg")
        else:
            s = prepare(ext, layout, x, inputs)
            var = np.nanmean(s, axis=1) + (ext.t_ref or 0.0)
            before = _point_signature(ext, layout, xb, eb, inputs, prob.meas, x)
            after = _point_signature(ext, layout, x, exts, inputs, prob.meas, x)
            if ext.name == "thermal_drift":
                model_y = (np.nanmean(s, axis=1)) * ext.coef[0] * 1e6
                xl = "air temperature / degC" if ext.variable == "temp_c" else "time / s"
                yl = "radial growth / ppm"
            else:
                var = np.nanmean(inputs.time_s, axis=1)
                model_y = np.nanmean(s, axis=1) * np.linalg.norm(ext.coef[:3])
                xl, yl = "time / s", "displacement along the shift / mm"
            series.update(x=var, before=before, after=after, model_x=var, model_y=model_y,
                          x_label=xl, y_label=yl)
        for k in ("x", "before", "after", "model_x", "model_y"):
            series[k] = np.asarray(series[k], dtype=float)
        out.append(series)
    return out


def _point_signature(ext, layout, x, exts, inputs, meas, x_final):
    """Per pose: radial growth (ppm) for thermal drift, displacement along the shift (mm) for a shift."""
    r = -(predict_extended(layout, x, exts, inputs) - meas)  # what the model misses
    if ext.name == "thermal_drift":
        v = predict_extended(layout, x, exts, inputs) - layout.base(x_final)[:3, 3]
        num = np.nansum(np.einsum("mkc,mkc->mk", v, r), axis=1)
        den = np.nansum(np.einsum("mkc,mkc->mk", v, v), axis=1)
        return num / den * 1e6
    u = ext.coef[:3] / max(np.linalg.norm(ext.coef[:3]), 1e-12)
    return np.nanmean(r @ u, axis=1)
