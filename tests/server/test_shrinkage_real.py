"""The real UR5 (one SMR near the flange axis): its wrist's weakly seen parameters shrunk toward
nominal and named, their standard errors the posterior's, the condition number of the rest."""

from __future__ import annotations

import numpy as np

from robocal.server.calibration.workflow import diagnose as workflow_diagnose
from robocal.server.calibration.workflow import load_data, model_file, run_method
from robocal.server.exports.params import entries
from robocal.solver.identifiability import SHRUNK_SHARE, condition_number, jacobian_rows
from tests.real import REAL


def test_the_real_ur5s_wrist_is_shrunk_named_and_left_out_of_the_condition_number():
    """Before: a5 and alpha5 held at nominal, so d5 came out -0.358 +- 0.031 mm, a precision
    only holding its partner gave it. Shrunk, d5 and a5 are named with the share of their
    estimate from the data (about a fifth), their standard errors near the prior's 1 mm, and the
    condition number is that of the identified parameters' Jacobian (shrunk ones left out)."""
    cell, meas = load_data(
        REAL / "ur5_jacobi" / "small" / "train.csv", REAL / "ur5_jacobi" / "cell.json"
    )
    cal = run_method(cell, meas, "ls-sum")
    assert {"d5", "a5"} <= set(cal.shrunk), cal.shrunk
    model = model_file(cal, cell, meas)
    ident = model.identified
    assert ident is not None and ident.prior
    shrunk = {s.parameter: s for s in ident.shrunk}
    assert set(shrunk) == set(cal.shrunk)
    rows = {r.parameter: r for r in ident.rows}
    for n, s in shrunk.items():
        assert 0.0 <= s.data_share < SHRUNK_SHARE and s.why, s
        assert rows[n].status == "shrunk toward nominal"
        # a posterior standard error: most of the prior's 1 mm / 1 deg is left
        se = rows[n].standard_error
        assert se is not None and 0.5 < se <= 1.0, (n, se)
    assert rows["theta6"].status == "held fixed"  # structurally redundant: still held
    model.identified = ident  # as read back from the file: the params export says it
    exported = {e.name: e.status for e in entries(model)}
    for n, s in shrunk.items():
        assert exported[n] == f"shrunk toward nominal ({s.data_share:.0%} from the data): {s.why}"
    names = cal.layout.names()
    identified = [i for i, n in enumerate(names) if n not in cal.fixed and n not in cal.shrunk]
    J = jacobian_rows(cal.layout, cal.x, meas.q, np.all(np.isfinite(meas.xyz), axis=-1))
    # of a subset of them that the data identifies alone (the prior resolves the rest)
    assert cal.condition <= 1.05 * condition_number(J[:, identified])
    with_shrunk = [i for i, n in enumerate(names) if n not in cal.fixed]
    assert condition_number(J[:, with_shrunk]) > 1e3 > cal.condition


def test_a_diagnosis_of_the_real_ur5_lists_the_shrunk_wrist_as_shrunk():
    """The diagnosis fits under the geometry's prior: its model's identified block lists d5 and
    a5 as shrunk toward nominal with their share from the data (not held fixed), the prior said,
    their standard errors the posterior's as the calibration's are."""
    cell, meas = load_data(
        REAL / "ur5_jacobi" / "small" / "train.csv", REAL / "ur5_jacobi" / "cell.json"
    )
    d, model = workflow_diagnose(cell, meas)
    ident = model.identified
    assert ident is not None and ident.prior and d.geometric is not None
    fixed = {f.parameter for f in ident.fixed}
    shrunk = {s.parameter: s for s in ident.shrunk}
    rows = {r.parameter: r for r in ident.rows}
    assert {"d5", "a5"} <= set(shrunk) and not fixed & set(shrunk), (fixed, shrunk)
    assert set(shrunk) == set(d.geometric.shrunk)
    for n, s in shrunk.items():
        assert s.data_share == round(d.geometric.shrunk[n].share, 6) and s.why, s
        assert rows[n].status == "shrunk toward nominal"
        se = rows[n].standard_error
        assert se is not None and 0.5 < se <= 1.0, (n, se)
    assert rows["theta6"].status == "held fixed"
