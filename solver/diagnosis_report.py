"""The diagnosis report (FORMATS.md section 5) and the data of its figures, in edge units."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .effects import Extension, joint_basis, joint_offsets, point_shift, prepare
from .extended import predict_extended
from .finite import finite
from .kinematics import predict_rows
from .report_blocks import (
    Alternative,
    CrossValidation,
    ExtrapolationReport,
    Significance,
    StabilityReport,
)
from .screen import Outlier
from .selection import rmse_gain_interval


def parameters(ext: Extension, basis: np.ndarray | None) -> dict:
    """An extension's fitted parameters in mm, degrees, ppm and seconds."""
    return ext.kind.parameters(ext, basis)


def evidence(
    ext: Extension, p: dict, before: float, after: float, decision: dict, m: int, half=None
) -> str:
    """One sentence a person can check against the figure. ext and p: the effect as fitted
    (whole); half: the deployed half-way model's held-out RMS (before, after), when it is."""
    gain = (
        f"modelling it cuts the held-out RMS from {before:.4f} to {after:.4f} mm over {m} poses "
        f"(p = {decision['p_value']:.4f} against this campaign's own null, "
        f"{decision['candidates']} candidates tried"
        + (
            ": the weight-carrying joints' one stiffness, tested alone once no effect of the "
            "whole vocabulary held)"
            if decision.get("suspect")
            else ")"
        )
    )
    if half is not None:
        gain += (
            f"; the model deploys it at half that size, which cuts the held-out RMS from "
            f"{half[0]:.4f} to {half[1]:.4f} mm"
        )
    return ext.kind.evidence(ext, p, gain)


def _label(exts) -> str:
    return "+".join(["geometric"] + [e.label() for e in exts])


@dataclass
class Score:
    """A model's held-out figures (mm): the geometric baseline's, or the final model's."""

    model: str  # geometric, then each effect: geometric+joint_compliance(2)
    holdout_rmse_mm: float
    holdout_max_mm: float


@dataclass
class WholeEffect:
    """An effect deployed half way (solver.hedge), as the selection judged it: fitted whole, its
    held-out figures, gain interval, parameters and their standard errors."""

    holdout_rmse_before_mm: float
    holdout_rmse_after_mm: float
    holdout_max_before_mm: float
    holdout_max_after_mm: float
    holdout_gain_interval_mm: list[float]
    parameters: dict[str, Any]
    uncertainty: dict[str, Any] | None = None


@dataclass
class Finding:
    """An effect judged real, with the held-out evidence for it (an entry of `effects`)."""

    name: str
    joint: int | None  # joints from 1; None for an effect of no joint
    own: dict[str, Any]  # the effect kind's own keys (harmonic, at_s), as its report_keys name
    evidence: str  # one sentence a person can check
    holdout_rmse_before_mm: float
    holdout_rmse_after_mm: float
    holdout_max_before_mm: float
    holdout_max_after_mm: float
    holdout_gain_interval_mm: list[float]
    significance: Significance
    alternatives: list[Alternative]  # candidates the data could not tell apart from it
    parameters: dict[str, Any]  # in mm, degrees, ppm and seconds
    uncertainty: dict[str, Any] | None = None  # each parameter's standard error, once estimated
    whole_effect: WholeEffect | None = None  # the effect fitted whole, when deployed half way

    @property
    def harmonic(self) -> int | None:
        """joint_periodic's multiple of the angle; None for the other effects."""
        return self.own.get("harmonic")

    def to_json(self) -> dict[str, Any]:
        """The entry as FORMATS.md section 5 has it (joint and uncertainty only when known)."""
        out: dict[str, Any] = {"name": self.name}
        if self.joint is not None:
            out["joint"] = self.joint
        out.update(self.own)
        out.update({k: v for k, v in asdict(self).items() if k not in ("name", "joint", "own")})
        out["alternatives"] = [a.to_json() for a in self.alternatives]
        if self.uncertainty is None:
            del out["uncertainty"]
        if self.whole_effect is None:
            del out["whole_effect"]
        elif self.whole_effect.uncertainty is None:
            del out["whole_effect"]["uncertainty"]
        return out


@dataclass
class Report:
    """A diagnosis's report (FORMATS.md section 5): the effects found, most important first, and
    what a person needs to check them."""

    noise_floor_mm: float | None
    noise_floor_source: str | None
    baseline: Score
    effects: list[Finding]
    final: Score
    poses: int
    readings: int
    candidates_tested: int
    unexplained: dict | None = None  # what the final model leaves (solver/unexplained.py)
    outliers: list[Outlier] | None = None  # readings excluded as gross errors, when screened
    extrapolation: ExtrapolationReport | None = None  # the final model off its training region
    stability: StabilityReport | None = None  # resamples of a small campaign (solver/stability.py)
    # per phase (its name, as the clock has it: a map, not a record), then the total
    seconds: dict[str, float] = field(default_factory=dict)
    cross_validation: CrossValidation | None = None  # folds, fits, candidates

    def to_json(self) -> dict[str, Any]:
        """The report as report.json has it, keys in section 5's order (the optional blocks only
        when there is one)."""
        out: dict[str, Any] = {
            "schema": 1,
            "noise_floor_mm": self.noise_floor_mm,
            "noise_floor_source": self.noise_floor_source,
            "baseline": asdict(self.baseline),
            "effects": [e.to_json() for e in self.effects],
            "final": asdict(self.final),
            "poses": self.poses,
            "readings": self.readings,
            "candidates_tested": self.candidates_tested,
        }
        if self.unexplained is not None:
            out["unexplained"] = self.unexplained
        if self.outliers is not None:
            out["outliers"] = [o.to_json() for o in self.outliers]
        if self.extrapolation is not None:
            out["extrapolation"] = self.extrapolation.to_json()
        if self.stability is not None:
            out["stability"] = self.stability.to_json()
        out["seconds"] = self.seconds
        out["cross_validation"] = (
            {} if self.cross_validation is None else asdict(self.cross_validation)
        )
        return out


def build_report(diag, steps, base, final, exts, x, floor, source, n_candidates, hedged=None):
    """Each extension's parameters (in step order) and the report: FORMATS.md section 5, plus what
    a person needs to check it (effects most important first).

    hedged (solver.hedge.Hedged): the model deployed half way; each effect's figures are then the
    half-way model's, and what the selection judged (the effect fitted whole) its `whole_effect`.
    """
    layout, inputs = diag.prob.layout, diag.inputs
    m = diag.prob.q.shape[0]
    effects, params = [], []
    whole = exts if hedged is None else hedged.whole[1]
    deployed = [s[1:3] for s in steps] if hedged is None else hedged.steps(diag, steps, base)
    for (_, before, after, decision), fitted, full, (b, a) in zip(steps, exts, whole, deployed):
        basis = joint_basis(fitted, layout, diag.x0, inputs) if fitted.is_joint else None
        p, pw = parameters(fitted, basis), parameters(full, basis)
        params.append(p)
        interval = list(decision["holdout_gain_interval_mm"])
        half = None if hedged is None else (b.rmse, a.rmse)
        effects.append(
            Finding(
                name=fitted.name,
                joint=None if fitted.joint is None else fitted.joint + 1,
                own={k: getattr(fitted, k) for k in fitted.kind.report_keys},
                evidence=evidence(full, pw, before.rmse, after.rmse, decision, m, half),
                holdout_rmse_before_mm=b.rmse,
                holdout_rmse_after_mm=a.rmse,
                holdout_max_before_mm=b.maxerr,
                holdout_max_after_mm=a.maxerr,
                holdout_gain_interval_mm=(
                    interval if hedged is None else list(rmse_gain_interval(b.sq, a.sq, a.n))
                ),
                significance=Significance(*(decision[k] for k in ("z", "threshold", "p_value"))),
                alternatives=decision["alternatives"],
                parameters=p,
                whole_effect=None
                if hedged is None
                else WholeEffect(
                    before.rmse, after.rmse, before.maxerr, after.maxerr, interval, pw
                ),
            )
        )
    effects.sort(key=lambda e: e.holdout_rmse_after_mm - e.holdout_rmse_before_mm)
    return params, Report(
        noise_floor_mm=floor,
        noise_floor_source=source,
        baseline=Score("geometric", base.rmse, base.maxerr),
        effects=effects,
        final=Score(_label(exts), final.rmse, final.maxerr),
        poses=m,
        readings=int(diag.prob.mask.sum()),
        candidates_tested=n_candidates,
    )


@dataclass(frozen=True)
class EffectFigure:
    """The data of a found effect's figure: its signature per pose, before and after."""

    name: str  # the effect kind
    label: str  # as the report names the effect: joint_compliance(2)
    x: np.ndarray  # per pose, the effect's variable
    before: np.ndarray  # the residual's signature fitted without the effect
    after: np.ndarray  # ... with the final model
    expected: np.ndarray  # what the effect leaves once geometry absorbed what it can
    x_label: str
    y_label: str


def figure_series(diag, steps, exts, x, hedged=None) -> list[EffectFigure]:
    """For each found effect, its signature in the residuals against its variable, before and after.

    `before` is the residual of the model fitted without the effect, `expected` what the effect
    leaves in such residuals once the geometric parameters have absorbed what they can (its
    displacement minus the projection on the geometric Jacobian): the points should follow it.
    `after` is the residual of the final model (x, exts). hedged: that model is half way
    (solver.hedge); `expected` is then the effect fitted whole, which the points before follow.
    """
    from .extended import fit_extended

    prob, inputs, layout = diag.prob, diag.inputs, diag.prob.layout
    mask = prob.mask
    pose = np.nonzero(mask)[0]
    m = prob.q.shape[0]
    meas = prob.meas[mask]
    r_after = predict_extended(layout, x, exts, inputs)[mask] - meas
    if hedged is not None:
        x, exts = hedged.whole
    bases = [prepare(e, layout, diag.x0, inputs) for e in exts]
    dq = joint_offsets(exts, bases, layout.robot.n_joints)
    idx = np.flatnonzero(diag.free)
    p, Jt, Jq = predict_rows(layout, x, inputs.q, mask, idx, dq=dq, joint_cols=True)
    Q, _ = np.linalg.qr(finite(Jt.reshape(len(idx), -1).T, "an effect's Jacobian"))
    out = []
    for i, ext in enumerate(exts):
        if ext.is_joint:
            D = Jq[ext.joint] * (bases[i] @ ext.coef)[pose][:, None]
        else:
            D, _ = point_shift(ext, bases[i][mask], p, ext.kind.origin(ext, layout, x))
        D_res = D - (Q @ (Q.T @ D.ravel())).reshape(D.shape)
        others = [e for j, e in enumerate(exts) if j != i]
        xb, eb, _ = fit_extended(
            prob, inputs, diag.x0, diag.free, others, start=diag.start, prior=diag.prior
        )
        r_before = predict_extended(layout, xb, eb, inputs)[mask] - meas
        sig = _signature(ext, Jq, p, layout, x, pose, m)
        expected = np.asarray(sig(-D_res), dtype=float)
        axes = ext.kind.figure(ext, inputs, expected)  # the variable and the axes' labels
        out.append(
            EffectFigure(
                name=ext.name,
                label=ext.label(),
                x=np.asarray(axes["x"], dtype=float),
                before=np.asarray(sig(r_before), dtype=float),
                after=np.asarray(sig(r_after), dtype=float),
                expected=expected,
                x_label=axes["x_label"],
                y_label=axes["y_label"],
            )
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
