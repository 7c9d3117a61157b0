"""The solver tests' simulated default cell (tests/sim.py, kept free of the server) is the
server's default cell, and the server builds a campaign's Problem from a cell in one place."""

import numpy as np

from robocal.drivers.cell import VirtualCell
from robocal.server.calibration import workflow
from robocal.server.formats.cell_json import default_cell
from tests import sim


def test_the_solver_tests_default_cell_is_the_servers():
    ours, theirs = sim.default_cell(), default_cell()
    assert ours.robot == theirs.robot and ours.base is None and theirs.base is None
    assert list(ours.targets) == list(theirs.targets)
    for name in theirs.targets:
        np.testing.assert_array_equal(ours.targets[name], theirs.targets[name])


def test_cell_problem_takes_the_cells_base_and_given_tracker_spec():
    cell = default_cell()
    meas = VirtualCell.random(cell.robot, cell.targets, seed=1).campaign(10, seed=1)
    p = workflow.cell_problem(cell, meas.select_targets(("C", "A")))
    assert p.target_names == ("C", "A") and p.tracker_spec is None and p.base_guess is None
    np.testing.assert_array_equal(p.targets, [cell.targets["C"], cell.targets["A"]])
    cell.base, cell.tracker_spec_given = np.eye(4), True
    p = workflow.cell_problem(cell, meas)
    assert p.tracker_spec == cell.tracker and np.array_equal(p.base_guess, np.eye(4))
