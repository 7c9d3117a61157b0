"""The adaptive campaign's extended refit is made under the calibration's prior, as the
calibration itself was: without effects it is the calibration."""

from __future__ import annotations

import numpy as np

from robocal.server.acquisition.adaptive_effects import extended_fit
from robocal.solver.calibrate import calibrate
from robocal.solver.fit_errors import calibration_errors
from tests.solver.test_shrinkage import ONE, campaign, drawn_from_the_prior

SEED = 4  # the UR5 with one SMR 0.5 mm off the flange axis: d5 and a5 shrunk


def test_the_refit_keeps_the_shrunk_parameters_where_the_calibration_put_them():
    """Fitted without the prior, the shrunk d5 and a5 wandered by their unshrunk standard
    errors (millimetres) from the calibration the campaign's next poses are chosen by."""
    prob, meas = campaign(SEED, ONE, drawn_from_the_prior(SEED, ()), n_poses=40)
    cal = calibrate(prob, "ls-sum")
    assert {"d5", "a5"} <= set(cal.shrunk), cal.shrunk
    column = calibration_errors(cal, prob.q, prob.meas).column
    fit = extended_fit(cal, meas, column, ())
    n = cal.layout.n_geo
    assert np.abs(fit.x[:n] - cal.x[:n]).max() <= 1e-5 * np.abs(cal.x[:n]).max()
