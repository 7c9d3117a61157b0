"""A small campaign's weak effects deployed half way between geometry and the extended fit
(issue 21, point 3).

On 40 poses or fewer an effect that removes under WEAK_GAIN of geometry's held-out RMS is within
what the fit's own noise gives: its coefficient trades with the geometry, and on the poses the arm
visits later it helps or hurts by a few per cent alike. The deployed model is then the average of
the two (geometry's parameters and the extended fit's, each half; the effects at half their fitted
size), the simplest model average when the data cannot choose between them. Measured (real
campaigns fitted on a subset, tested on the rest): the real one-SMR UR5's random
30- and 40-pose subsets gain 5.5-11.6 % held out on their own poses and test 0.92-1.08x geometry on
the other ~960 poses (seed 0: four above 1.02x, seed 1: one); half way none is above 1.002x and
the mean goes 1.004 -> 0.978 and 0.960 -> 0.958. The real IRB 120 and QKM halves and folds (18-36
poses) gain 23-78 %, the bench's 30-40-pose effect cases 21-83 %: untouched.

Every figure the report gives of the deployed model is the half-way model's: each effect's
held-out figures and gain interval blend each fold's two fits up to that effect (half_way_steps),
and its standard errors are the half-way estimator's (half_way_errors); what the selection judged,
the effect fitted whole, is kept beside them (the report's `whole_effect`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fit_errors import extended_fit_rows
from .postfit import post_fit
from .prior import PriorTerms
from .uncertainty import CLUSTERED, ParameterErrors, Rows
from .vocabulary import Extension

WEAK_GAIN = 0.15  # of geometry's held-out RMS: UR5 subsets 0.055-0.116, IRB/QKM/bench >= 0.21


@dataclass(frozen=True)
class Hedged:
    """The model half way: its parameters, effects, held-out figures, and the gain that chose it."""

    x: np.ndarray
    exts: list
    cv: object  # solver.diagnose.CV of the half-way model: each fold's two fits blended
    gain: float  # the extended model's held-out gain over geometry, a share of geometry's RMS
    geometry: np.ndarray  # geometry's parameters fitted on every pose
    whole: tuple  # (parameters, extensions) of the extended fit on every pose, effects whole

    def steps(self, diag, steps, base) -> list[tuple]:
        """Per selection step, the half-way model's (before, after) CVs (see half_way_steps)."""
        return half_way_steps(diag, steps, base, self.cv)

    def errors(self, diag) -> ParameterErrors:
        """The deployed (half-way) model's standard errors (see half_way_errors)."""
        return half_way_errors(diag, self.geometry, *self.whole)


def halved(exts, x_ext, x_geo):
    """Parameters half way between the two fits, and the effects at half their size."""
    half = [Extension(**{**e.__dict__, "coef": 0.5 * np.asarray(e.coef)}) for e in exts]
    return 0.5 * (np.asarray(x_ext) + np.asarray(x_geo)), half


def hedge(diag, base, final, x, exts) -> Hedged | None:
    """The half-way model when the final model's held-out gain over geometry (base) is weak;
    None when it is not (or nothing is named). Its held-out figures blend each fold's two fits."""
    if not exts:
        return None
    gain = 1.0 - final.rmse / base.rmse
    if gain >= WEAK_GAIN:
        return None
    fits: dict[int | str, tuple] = {
        f: halved(final.fits[f][1], final.fits[f][0], base.fits[f][0])
        for f in range(len(diag.folds))
    }
    x_geo = np.asarray(base.fits["all"][0], dtype=float)
    xh, eh = fits["all"] = halved(exts, x, x_geo)
    return Hedged(xh, eh, diag.held_out(fits), float(gain), x_geo, (np.asarray(x), list(exts)))


def half_way_steps(diag, steps, base, final_cv) -> list[tuple]:
    """Per selection step (extension, before CV, after CV, decision), the CVs of the half-way
    models before and after it: each fold's fit of the model up to that effect blended with
    geometry's fit on that fold, as the deployed model is; geometry stays itself (blended with
    itself). The last step's after is the deployed model's own (final_cv)."""
    blended: dict[int, object] = {id(base): base}

    def half(cv):
        if id(cv) not in blended:
            fits = {f: halved(cv.fits[f][1], cv.fits[f][0], base.fits[f][0]) for f in cv.fits}
            blended[id(cv)] = diag.held_out(fits)
        return blended[id(cv)]

    if steps:
        blended[id(steps[-1][2])] = final_cv
    return [(half(before), half(after)) for _, before, after, _ in steps]


def half_way_errors(diag, x_geo, x_ext, exts) -> ParameterErrors:
    """Covariance of the half-way model: geometry's parameters and the extended fit's averaged,
    the effects' coefficients halved.

    Both fits solve their estimating equations on the same readings, so their errors are
    correlated (closely, for the parameters the effect does not trade with); the average's
    covariance needs that cross term: (C_gg + C_ee + C_ge + C_eg) / 4. Both fits are stacked
    as one estimator (block-diagonal rows over [geometry's columns | the extended fit's], the
    rows of a pose sharing its readings' error): its pose-clustered sandwich (CR2, each fit's
    residuals adjusted by its own hat matrix) has the cross-covariance in the meat, and the
    prior both fits carry scores the same draw in both. A halved coefficient's covariance is a
    quarter of the whole one's (its standard error half); a periodic term's phase does not
    change with its size, and propagated at the halved coefficients keeps its standard error."""
    prob, inputs, x0, free, prior = diag.prob, diag.inputs, diag.x0, diag.free, diag.prior
    geo, _, col_g, _ = extended_fit_rows(prob, inputs, x0, free, x_geo, [])
    ext, names, column, degrees = extended_fit_rows(prob, inputs, x0, free, x_ext, exts)
    ng, ne = geo.J.shape[1], ext.J.shape[1]
    Jg = np.hstack([geo.J, np.zeros((len(geo.r), ne))])
    Je = np.hstack([np.zeros((len(ext.r), ng)), ext.J])
    rows = Rows.stack(
        [
            Rows(Jg, Jg, geo.r, geo.pose, geo.stage),
            Rows(Je, Je, ext.r, ext.pose, ext.stage + 1),  # each fit its own residual variance
        ]
    )
    terms = None
    if prior is not None:
        lay = prob.layout.n_params
        pg, pe = prior.terms(col_g[:lay], ng), prior.terms(column[:lay], ne)
        n = ng + ne
        info, res, meat = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
        for at, t in ((slice(0, ng), pg), (slice(ng, n), pe)):
            info[at, at], res[at, at], meat[at, at] = t.information, t.residual, t.meat
        # the geometric columns are the extended fit's first ng, in the same order
        meat[:ng, ng : 2 * ng] = meat[ng : 2 * ng, :ng] = pg.meat
        terms = PriorTerms(info, meat, res)
    post = post_fit(lambda: [rows], prior=terms)
    L = 0.5 * np.hstack([np.eye(ne)[:, :ng], np.eye(ne)])  # geometry's half, the extended half
    return ParameterErrors(
        tuple(names),
        column,
        L @ post.clustered @ L.T,
        degrees,
        HALF_WAY_ESTIMATOR,
        post.poses,
        None,  # the two fits' plain estimates share the readings: no independent-row figure
    )


HALF_WAY_ESTIMATOR = (
    f"{CLUSTERED} of the half-way model: geometry's and the extended fit's parameters averaged "
    "with their cross-covariance, the effects' coefficients halved"
)
