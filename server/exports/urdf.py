"""A URDF of the calibrated arm: joint origins that reproduce its DH/MDH chain with beta."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np

from robocal.server.formats.model_json import ModelFile

from .frames import rpy_from_matrix, segments

AXES = ("1 0 0", "0 1 0", "0 0 1")
ROOT = "tracker"  # the measurement frame the base was identified in


def _num(v: float) -> str:
    # repr: the shortest text that reads back as the same double (URDF readers parse doubles)
    return repr(float(v) + 0.0)  # + 0.0: no "-0.0"


def _origin(parent: ET.Element, T: np.ndarray, scale: float) -> None:
    """An <origin> of transform T (mm), in metres as URDF wants."""
    xyz = " ".join(_num(v * scale) for v in T[:3, 3])
    rpy = " ".join(_num(v) for v in rpy_from_matrix(T[:3, :3]))
    ET.SubElement(parent, "origin", xyz=xyz, rpy=rpy)


def _fixed(robot: ET.Element, name: str, parent: str, child: str, T, scale: float) -> None:
    j = ET.SubElement(robot, "joint", name=name, type="fixed")
    _origin(j, T, scale)
    ET.SubElement(j, "parent", link=parent)
    ET.SubElement(j, "child", link=child)


def urdf_text(model: ModelFile, source: str = "model.json") -> str:
    """The URDF document: tracker -> base_link (fixed, the calibrated base), link_1 ... link_N
    (revolute joint_1 ... joint_N, origins from the calibrated chain, limits from the model),
    flange (fixed) and one fixed link per SMR (smr_A, ...), lengths in metres."""
    scale = 1e-3
    r = model.robot
    root = ET.Element("robot", name=f"{r.name}_calibrated")
    note = (
        f" robocal export of {source}: {r.name}, {r.convention.upper()} with beta, calibrated"
        f" joint origins (method {model.method or 'unknown'}). Joint values are the"
        " controller's readings (the zero offsets theta are in the origins). Lengths in m."
        " Geometry only: the model's extensions are not in a URDF. Effort and velocity limits"
        " are not known to the calibration: 0, take them from the vendor's description. "
    )
    # "--" may not appear inside an XML comment (a file or robot name could bring one)
    root.append(ET.Comment(re.sub("-(?=-)", "- ", note)))
    links = [ROOT, "base_link"] + [f"link_{i}" for i in range(1, r.n_joints + 1)] + ["flange"]
    links += [f"smr_{t}" for t in model.targets]
    for name in links:
        ET.SubElement(root, "link", name=name)
    _fixed(root, "base_joint", ROOT, "base_link", np.asarray(model.base, dtype=float), scale)
    segs, tail = segments(r)
    parent = "base_link"
    for i, (seg, joint) in enumerate(zip(segs, r.joints), start=1):
        j = ET.SubElement(root, "joint", name=f"joint_{i}", type="revolute")
        _origin(j, seg.origin, scale)
        ET.SubElement(j, "parent", link=parent)
        ET.SubElement(j, "child", link=f"link_{i}")
        ET.SubElement(j, "axis", xyz=AXES[seg.axis])
        lo, hi = joint.limits
        ET.SubElement(j, "limit", lower=_num(lo), upper=_num(hi), effort="0", velocity="0")
        parent = f"link_{i}"
    _fixed(root, "flange_joint", parent, "flange", tail, scale)
    for t, p in model.targets.items():
        T = np.eye(4)
        T[:3, 3] = p
        _fixed(root, f"smr_{t}_joint", "flange", f"smr_{t}", T, scale)
    ET.indent(root, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
