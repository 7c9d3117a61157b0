"""ISO 9283 figures on synthetic attained positions whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.solver.iso9283 import (
    cube_points,
    distance_figures,
    multidirectional_variation,
    position_figures,
)


def test_accuracy_is_the_barycentres_offset_and_repeatability_its_spread():
    commanded = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]])
    # point 0: four positions on a square of half-side 1 around (0.3, -0.4, 0): every l_j = sqrt2
    ring = np.array([[1, 1, 0], [1, -1, 0], [-1, 1, 0], [-1, -1, 0]], dtype=float)
    a0 = np.array([0.3, -0.4, 0.0]) + ring
    # point 1: two at the commanded point, two 2 mm off along z: barycentre 1 mm up
    a1 = commanded[1] + np.array([[0, 0, 0], [0, 0, 0], [0, 0, 2], [0, 0, 2]], dtype=float)
    f = position_figures(np.stack([a0, a1]), commanded)
    np.testing.assert_allclose(f.ap_xyz, [[0.3, -0.4, 0.0], [0.0, 0.0, 1.0]], atol=1e-12)
    np.testing.assert_allclose(f.ap, [0.5, 1.0])
    np.testing.assert_allclose(f.l_bar, [np.sqrt(2), 1.0])
    np.testing.assert_allclose(f.s_l, [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(f.rp, [np.sqrt(2), 1.0])


def test_repeatability_of_a_gaussian_cloud_matches_its_law():
    rng = np.random.default_rng(1)
    sigma = 0.02
    a = rng.normal(0.0, sigma, (1, 20000, 3)) + [5.0, 0.0, 0.0]
    f = position_figures(a, np.zeros((1, 3)))
    # distance to the centre of a 3-D Gaussian: Maxwell, mean 2 sigma sqrt(2/pi), var (3 - 8/pi)
    mean = 2 * sigma * np.sqrt(2 / np.pi)
    sd = sigma * np.sqrt(3 - 8 / np.pi)
    assert f.rp[0] == pytest.approx(mean + 3 * sd, rel=0.02)
    assert f.ap[0] == pytest.approx(5.0, abs=1e-3)


def test_directional_variation_is_the_widest_gap_between_approach_barycentres():
    a = np.array([[[0, 0, 0], [0, 0, 0], [0.3, 0, 0], [0.3, 0, 0], [0, 0.4, 0], [0, 0.4, 0]]])
    v = multidirectional_variation(a, [0, 0, 1, 1, 2, 2])
    assert v[0] == pytest.approx(0.5)


def test_distance_accuracy_and_repeatability():
    commanded = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]])
    stretch = np.array([0.1, 0.3, 0.2])  # the second point lands this far beyond, per cycle
    a = np.zeros((2, 3, 3))
    a[1] = commanded[1] + np.outer(stretch, [1, 0, 0])
    d = distance_figures(a, commanded, [(0, 1)])
    assert d.ad[0] == pytest.approx(0.2)
    np.testing.assert_allclose(d.ad_xyz[0], [0.2, 0, 0], atol=1e-12)
    assert d.rd[0] == pytest.approx(3 * 0.1)


def test_cube_points_sit_on_the_measuring_planes_diagonals():
    centre, side = np.array([1000.0, -200.0, 800.0]), 400.0
    p = cube_points(centre, side)
    assert p.shape == (5, 3)
    np.testing.assert_allclose(p[0], centre)
    # P2..P5 are 0.4 of the plane's diagonal (side * sqrt3) from the centre, opposite in pairs
    np.testing.assert_allclose(np.linalg.norm(p[1:] - centre, axis=1), 0.4 * side * np.sqrt(3))
    np.testing.assert_allclose(p[1] + p[3], 2 * centre)
    np.testing.assert_allclose(p[2] + p[4], 2 * centre)
    # all in one plane through the centre, x - y = 0 in the cube's axes
    local = p - centre
    np.testing.assert_allclose(local[:, 0] - local[:, 1], 0, atol=1e-9)
    # inside the cube, 10 % of the diagonal from the corners
    assert np.all(np.abs(local) <= side / 2)
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)
    np.testing.assert_allclose(cube_points(centre, side, R) - centre, local @ R.T)


def test_shapes_are_refused():
    with pytest.raises(ValueError):
        position_figures(np.zeros((2, 1, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError):
        position_figures(np.zeros((2, 3, 3)), np.zeros((3, 3)))
