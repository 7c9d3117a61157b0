"""Gross-outlier screening through the commands' workflow (moved from tests/solver/test_screen.py,
which keeps the solver's own screening): real campaigns, and the fits that screen first."""

import numpy as np

from robocal.drivers.cell import displace
from robocal.server.calibration import workflow
from robocal.server.formats.cell_json import default_cell
from robocal.solver.kinematics import predict
from tests.real import CAMPAIGNS, campaign_files
from tests.solver.test_screen import campaign

CELL = default_cell()


def test_real_campaigns_keep_their_readings():
    """Real arms leave hundreds of um unmodelled: that is no gross error (none flagged in these)."""
    for name in CAMPAIGNS:
        cell, meas = workflow.load_data(*campaign_files(name))
        assert workflow.screen_campaign(cell, meas).count <= 0.02 * meas.n_readings


def test_minimax_with_outliers_close_to_without():
    """Screened, minimax on a campaign with outliers predicts held-out poses about as well as on
    the clean campaign; unscreened it does not."""
    worse = []
    for seed in range(4):
        _, meas = campaign(seed, 60)
        fit, hold = meas.subset(np.arange(40)), meas.subset(np.arange(40, 60))
        dirty = workflow.Measurements(
            fit.pose_ids,
            fit.q,
            fit.target_names,
            displace(fit.xyz, seed, 0.03)[0],
            fit.time_s,
            fit.temp_c,
        )

        def held_out(m, screening):
            cal = workflow.run_method(CELL, m, "minimax", screening=screening)
            err = predict(cal.layout, cal.x, hold.q) - hold.xyz  # noqa: B023 (called in this iteration)
            return np.sqrt(np.nanmean(np.sum(err**2, axis=-1)))

        clean = held_out(fit, False)
        assert held_out(dirty, True) <= 1.2 * clean
        worse.append(held_out(dirty, False) / clean)
    assert max(worse) > 2  # the outliers matter when kept


def test_too_few_poses_for_the_geometry_leave_the_fit_unscreened():
    """Two poses cannot fit the geometry: nothing screened, the reason kept, nominal still runs."""
    _, meas = campaign(4, 40)
    cal = workflow.run_method(CELL, meas.subset(np.arange(2)), "nominal")
    assert cal.screening.skipped
