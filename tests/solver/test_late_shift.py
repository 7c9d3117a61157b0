"""The last poses of a campaign moved together (a bumped tracker after the selection's last
possible split): found with their shift, and never on residuals of the same scatter."""

import numpy as np
import pytest

from robocal.solver.selection import EDGE_POSES
from robocal.solver.shift_scan import late_shift


def _campaign(rng, m=60, K=3, sigma=0.01):
    points = rng.uniform(-1500, 1500, size=(m, K, 3))
    return sigma * rng.normal(size=(m, K, 3)), points


# one SMR's last reading alone is an outlier as well as a shift (test_one_reading_off_is_no_shift)
@pytest.mark.parametrize(
    "K, k", [(K, k) for K in (1, 3) for k in range(1, EDGE_POSES) if K * k > 1]
)
def test_the_last_poses_moved_together_are_named_with_their_shift(K, k):
    rng = np.random.default_rng(10 * K + k)
    r, points = _campaign(rng, K=K)
    order = rng.permutation(len(r))  # time order: not the file's
    shift = np.array([0.12, -0.08, 0.05])
    r[order[-k:]] += shift
    late = late_shift(r, order, points)
    assert late is not None
    assert list(late.poses) == list(order[-k:])
    np.testing.assert_allclose(late.shift_mm, shift, atol=0.03)
    assert late.rest_mm == pytest.approx(0.01 * np.sqrt(3), rel=0.3) and late.left_mm < 0.03


def test_a_shift_of_the_last_poses_that_started_earlier_is_not_theirs():
    """A shift from the fifth-last pose on is the selection's base_shift (EDGE_POSES on each
    side of its split); one pose amid the campaign as far off makes the last ones no exception."""
    rng = np.random.default_rng(1)
    r, points = _campaign(rng)
    order = np.arange(len(r))
    moved = r.copy()
    moved[-EDGE_POSES:] += [0.2, 0.0, 0.0]
    assert late_shift(moved, order, points) is None
    moved = r.copy()
    moved[-2:] += [0.2, 0.0, 0.0]
    moved[20] += [0.0, 0.3, 0.0]
    assert late_shift(moved, order, points) is None


def test_one_reading_off_is_no_shift():
    """The last pose of a one-SMR campaign off by 0.2 mm: an outlier as much as a bump."""
    rng = np.random.default_rng(4)
    r, points = _campaign(rng, K=1)
    r[-1] += [0.2, 0.0, 0.0]
    assert late_shift(r, np.arange(len(r)), points) is None
    r[-2] += [0.2, 0.0, 0.0]  # the pose before it too: the same shift twice
    assert late_shift(r, np.arange(len(r)), points) is not None


def test_the_last_poses_moved_apart_are_no_rigid_shift():
    """Each of the last three SMR readings off in its own direction: no one rigid motion."""
    rng = np.random.default_rng(2)
    r, points = _campaign(rng, K=1)
    points[-3:] = [[[1000.0, 0, 0]], [[1001.0, 0, 0]], [[1000.0, 1.0, 0]]]  # a rotation's lever
    r[-3:] += [[[0.2, 0, 0]], [[-0.2, 0.0, 0]], [[0.0, 0.0, 0.25]]]
    assert late_shift(r, np.arange(len(r)), points) is None


def test_scatter_alone_never_names_a_late_shift():
    """2,000 campaigns of Gaussian scatter (one or three SMRs, 20 to 200 poses, missing readings),
    and the heavier tails of Student's t with 3 degrees of freedom: none."""
    rng = np.random.default_rng(3)
    for i in range(2000):
        m, K = int(rng.integers(20, 200)), int(rng.choice([1, 3]))
        r, points = _campaign(rng, m, K)
        if i % 2:
            r = 0.01 * rng.standard_t(3, size=r.shape)
        r[rng.random((m, K)) < 0.05] = np.nan
        assert late_shift(r, rng.permutation(m), points) is None, i
