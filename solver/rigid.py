"""Rigid registration of point sets in closed form (kabsch)."""

from __future__ import annotations

import numpy as np

from .finite import finite


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The rigid 4x4 transform T minimising sum ||T src - dst||^2 (points as rows)."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    U, _, Vt = np.linalg.svd(
        finite((src - cs).T @ (dst - cd), "the point-set registration's cross-covariance")
    )
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = cd - R @ cs
    return T
