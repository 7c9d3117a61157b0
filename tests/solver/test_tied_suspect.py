"""selection.tied_suspect: a tie with the best goes to the gravity-loaded joint's one stiffness."""

from __future__ import annotations

import numpy as np

from robocal.solver.selection import Scores, tied_suspect
from robocal.solver.variants import MIN_GAIN, T_SIMPLER
from robocal.solver.vocabulary import Extension

G = np.array([0.0, 0.0, -1.0])
W = np.ones(4)


def scores(pose_gains) -> Scores:
    """Scores of candidates with these per-pose gains on 20 poses of squared error 1 each."""
    pg = np.array(pose_gains, dtype=float)
    return Scores(20.0, np.ones(20), pg.sum(axis=1), pg, np.zeros(len(pg)), np.zeros(1))


def trial(first: Extension) -> list[Extension]:
    return [
        first,
        Extension("joint_compliance", joint=1, gravity=G, masses=W),  # joint 2's one stiffness
        Extension("joint_compliance", joint=1, gravity=G, masses=W, keep=np.ones(4, bool)),
    ]


rng = np.random.default_rng(0)
NOISY = 0.2 + 0.3 * rng.standard_normal((3, 20))  # gains no paired t over 20 poses tells apart


def test_a_tied_look_alike_gives_way_to_the_loaded_joints_stiffness():
    scale4 = Extension("joint_scale", joint=3)
    assert tied_suspect(trial(scale4), 0, scores(NOISY), 1, T_SIMPLER, MIN_GAIN) == 1
    # another joint most loaded, or no small campaign (joint None): the best stays
    assert tied_suspect(trial(scale4), 0, scores(NOISY), 2, T_SIMPLER, MIN_GAIN) == 0
    assert tied_suspect(trial(scale4), 0, scores(NOISY), None, T_SIMPLER, MIN_GAIN) == 0


def test_a_clear_winner_and_a_periodic_term_stay():
    clear = NOISY.copy()
    clear[1] = clear[0] - 0.4  # the stiffness 0.4 behind on every pose: t far above T_SIMPLER
    scale4 = Extension("joint_scale", joint=3)
    assert tied_suspect(trial(scale4), 0, scores(clear), 1, T_SIMPLER, MIN_GAIN) == 0
    periodic = Extension("joint_periodic", joint=1, harmonic=2)
    assert tied_suspect(trial(periodic), 0, scores(NOISY), 1, T_SIMPLER, MIN_GAIN) == 0


def test_a_stiffness_that_gains_nothing_is_not_named():
    idle = NOISY.copy()
    idle[1] = 0.0  # tied within the noise perhaps, but removes none of the held-out error
    scale4 = Extension("joint_scale", joint=3)
    assert tied_suspect(trial(scale4), 0, scores(idle), 1, T_SIMPLER, MIN_GAIN) == 0
