"""Non-geometric model extensions, each linear in its own parameters.

A joint extension adds a correction dq_j = basis(q) @ c to one joint's reading (cyclic gear
error, scale error, compliance under gravity). A point extension moves the predicted SMR centres
after the kinematics (links growing with temperature, the base moving during the campaign).
Bases are computed once per data set from the registered nominal model, so the extended model
stays linear in the new parameters and their Jacobian is the joint's column times the basis.
What each effect is (basis, parameters, report, file form) lives in its class in vocabulary.py,
beside the Extension that names it; the functions here only dispatch to it.
"""

from __future__ import annotations

import numpy as np

from .kinematics import Layout
from .vocabulary import Extension, Inputs


def joint_basis(ext: Extension, layout: Layout, x, inputs: Inputs) -> np.ndarray:
    """(m, P) basis of a joint extension: dq_joint = basis @ coef."""
    if not ext.is_joint:
        raise ValueError(f"{ext.name} is not a joint extension")
    return ext.kind.basis(ext, layout, x, inputs)


def point_basis(ext: Extension, layout: Layout, x, inputs: Inputs):
    """Per reading (m, K): the scalar that switches or scales a point extension."""
    if ext.is_joint:
        raise ValueError(f"{ext.name} is not a point extension")
    return ext.kind.basis(ext, layout, x, inputs)


def prepare(ext: Extension, layout: Layout, x, inputs: Inputs) -> np.ndarray:
    """The extension's basis on this data: (m, P) for joint extensions, (m, K) for point ones."""
    return (
        joint_basis(ext, layout, x, inputs) if ext.is_joint else point_basis(ext, layout, x, inputs)
    )


def joint_offsets(exts, bases, n_joints: int) -> np.ndarray | None:
    """Sum of the joint corrections (m, n) of the joint extensions."""
    dq = None
    for ext, B in zip(exts, bases):
        if ext.is_joint:
            if dq is None:
                dq = np.zeros((B.shape[0], n_joints))
            dq[:, ext.joint] += B @ ext.coef
    return dq


def point_shift(ext: Extension, s: np.ndarray, p: np.ndarray, origin: np.ndarray, coef=None):
    """Displacement (N, 3) of points p by a point extension and its Jacobian (P, N, 3).

    s is the extension's per-reading scalar; origin the point it acts about (`kind.origin`).
    """
    return ext.kind.shift(ext, s, p - origin, ext.coef if coef is None else coef)
