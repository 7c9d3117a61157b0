"""docs/formats.md, generated: the CSV files' columns from the readers' own names and bounds,
the JSON files' fields from their committed JSON Schemas (tests keep the page equal to this).

Regenerate: python -m robocal.server.formats.formats_doc
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from robocal.solver.configuration import CF_COLUMNS

from .campaign_csv import BOUNDS, EXTRAS, MEASURED
from .json_schema import MODELS, committed
from .targets_csv import ANGLE_BOUNDS, ORIENTATION

PAGE = Path(__file__).resolve().parents[2] / "docs" / "formats.md"
JOINTS = "q1..qN"  # one column per joint, in degrees, within the robot's joint limits
PREV = "prev_q1..prev_qN"  # the joints the arm came from before the pose
PREV_NOTE = (
    f"{PREV} (all or none on a row, the same on every row of a pose) are the joints the arm came "
    "from before the pose: where given, they set the direction of each joint's last motion "
    "(backlash) in place of the visit order (time_s, else the file order), so a file split or "
    "reordered keeps it. Given in radians beside q1..qN in degrees (over three poses or more, "
    "within the joint limits read as radians and spreading 1/57.3 as much as the joints; on one "
    "or two poses, within those limits and, read as radians, five times nearer the pose than "
    "read as degrees), or the other way round, they are refused naming the unit. Without them "
    "or time_s, the commands "
    "whose model has backlash (and `diagnose`, when it names backlash or the rows look sorted by "
    "a joint) warn that the file order is taken as the order of motion."
)


@dataclass(frozen=True)
class CsvFile:
    """One CSV file: what it is, its columns required and optional, who reads and writes it."""

    name: str
    what: str
    required: tuple[str, ...]
    optional: tuple[str, ...]
    read_by: str
    written_by: str
    note: str = ""


CSV_FILES = (
    CsvFile(
        "meas.csv",
        "a measurement campaign: one row per (pose, SMR) reading",
        ("pose", JOINTS, "target", *MEASURED),
        (*EXTRAS, PREV),
        "calibrate, evaluate, compare, diagnose, predict (as poses)",
        "simulate; the API's measurements.csv",
        "Rows of one pose repeat its joints exactly; a (pose, target) pair appears once; "
        "an SMR not measured at a pose has no row. " + PREV_NOTE,
    ),
    CsvFile(
        "poses.csv",
        "poses to predict SMR positions for",
        ("pose", JOINTS),
        (*EXTRAS, "target", PREV),
        "predict",
        "-",
        "A meas.csv is accepted: its measured columns are ignored. " + PREV_NOTE,
    ),
    CsvFile(
        "pred.csv",
        "predicted SMR positions",
        ("pose", "target", *MEASURED),
        (),
        "-",
        "predict",
    ),
    CsvFile(
        "targets.csv",
        "where the SMRs (or, with --tcp, the tool point) must go",
        ("pose", "target", *MEASURED),
        (JOINTS, *CF_COLUMNS, *EXTRAS, PREV, *ORIENTATION),
        "compensate, export --targets",
        "-",
        f"Every pose gives {JOINTS} (all or none: the starting joints, which keep their "
        f"configuration) or {', '.join(CF_COLUMNS)} (all or none: ABB's confdata, see "
        "[configuration.md](configuration.md)); a pose with neither is refused. "
        f"{', '.join(ORIENTATION)} (all three, degrees, Rz Ry Rx) give the tool's orientation "
        "with --tcp. " + PREV_NOTE,
    ),
    CsvFile(
        "joints.csv",
        "joint commands that put the SMRs where wanted",
        ("pose", JOINTS),
        ("predicted_error_mm",),
        "export --joints",
        "compensate",
    ),
)

JSON_FILES = {
    "cell": "the cell: robot, nominal SMRs, tracker, and optionally its devices",
    "model": "a calibrated model (calibrate, diagnose --model-out)",
    "report": "a diagnosis (diagnose); effect N is `effects[N-1]`, its figure REPORT_N_*.png",
    "verification": "an ISO 9283 verification run before and after compensation (acquire "
    "--verify; the API's GET /api/campaigns/{id}/verification), with its uncertainty and "
    "decisions; see acquisition.md",
}


def column_unit(column: str) -> str:
    """A column's unit and range, from the bounds the readers enforce."""
    if column in (JOINTS, PREV):
        return "deg, within the joint limits"
    if column in ORIENTATION:
        (lo, hi), unit = ANGLE_BOUNDS
        return f"{unit}, {lo:g} to {hi:g}"
    if column in BOUNDS:
        (lo, hi), why = BOUNDS[column]
        return f"{why.split(' (')[0]}, {lo:g} to {hi:g}"
    if column in CF_COLUMNS[:-1]:
        return "integer: the quadrant of joint " + column[2:] + ", within its limits"
    if column == CF_COLUMNS[-1]:
        return "integer: the arm configuration, 0 to 7"
    if column == "predicted_error_mm":
        return "mm"
    if column == "pose":
        return "label (any text)"
    if column == "target":
        return "SMR name, as in the cell"
    return ""


def csv_section(f: CsvFile) -> list[str]:
    lines = [
        f"### {f.name}",
        "",
        f"{f.what[0].upper()}{f.what[1:]}. Read by: {f.read_by}. Written by: {f.written_by}.",
        "",
        "| column | required | unit |",
        "| --- | --- | --- |",
    ]
    for c in f.required:
        lines.append(f"| `{c}` | yes | {column_unit(c)} |")
    for c in f.optional:
        lines.append(f"| `{c}` | no | {column_unit(c)} |")
    if f.note:
        lines += ["", f.note]
    return lines + [""]


def type_of(spec: dict) -> str:
    """A schema's type in a few words: number, array of ..., a link to a definition."""
    if "$ref" in spec:
        name = spec["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{name.lower()})"
    if "const" in spec:
        return f"`{json.dumps(spec['const'])}`"
    if "enum" in spec:
        return " or ".join(f"`{json.dumps(v)}`" for v in spec["enum"])
    for key in ("anyOf", "oneOf"):
        if key in spec:
            # a date is a string too: each kind said once
            kinds = list(dict.fromkeys(type_of(s) for s in spec[key] if s.get("type") != "null"))
            null = any(s.get("type") == "null" for s in spec[key])
            return " or ".join(kinds) + (" or null" if null else "")
    kind = spec.get("type", "any")
    if kind == "array":
        size = spec.get("minItems")
        fixed = f"{size} " if size is not None and size == spec.get("maxItems") else ""
        return f"array of {fixed}{type_of(spec.get('items', {}))}"
    if kind == "object" and isinstance(spec.get("additionalProperties"), dict):
        return f"object of {type_of(spec['additionalProperties'])}"
    unit = spec.get("description") if kind in ("number", "integer") else None
    return f"{kind} ({unit})" if unit in ("mm", "degrees") else kind


def bounds_of(spec: dict) -> str:
    """A field's size or range bound in a few words ("at most 16 keys", "-5000 to 5000")."""
    if "maxProperties" in spec:
        return f"{spec.get('minProperties', 0)} to {spec['maxProperties']} keys"
    if "maxItems" in spec and spec.get("minItems") != spec["maxItems"]:
        return f"{spec.get('minItems', 0)} to {spec['maxItems']} elements"
    if spec.get("type") in ("number", "integer") and "maximum" in spec and "minimum" in spec:
        return f"{_number(spec['minimum'])} to {_number(spec['maximum'])}"
    return ""


def _number(x: float) -> str:
    return f"{x:.0f}" if x == int(x) and abs(x) < 1e7 else f"{x:g}"


def fields_table(schema: dict) -> list[str]:
    required = set(schema.get("required", ()))
    lines = ["| field | type | required | meaning |", "| --- | --- | --- | --- |"]
    for name, spec in schema.get("properties", {}).items():
        meaning = spec.get("description", "")
        if spec.get("type") in ("number", "integer") and meaning in ("mm", "degrees"):
            meaning = ""
        bound = bounds_of(spec)
        meaning = f"{meaning}; {bound}" if meaning and bound else meaning or bound
        lines.append(
            f"| `{name}` | {type_of(spec)} | {'yes' if name in required else 'no'} | "
            f"{' '.join(meaning.split())} |"
        )
    return lines


def json_section(name: str) -> list[str]:
    schema = json.loads(committed(name).read_text(encoding="utf-8"))
    lines = [
        f"### {name}.json",
        "",
        f"{JSON_FILES[name][0].upper()}{JSON_FILES[name][1:]}. JSON Schema: "
        f"`robocal schema {name}` (server/formats/schema/{name}.schema.json).",
        "",
        *fields_table(schema),
        "",
    ]
    for def_name, spec in schema.get("$defs", {}).items():
        if "properties" not in spec:
            continue
        lines += [f"#### {def_name}", ""]
        if spec.get("description"):
            lines += [" ".join(spec["description"].split()), ""]
        lines += [*fields_table(spec), ""]
    return lines


def generated() -> str:
    """The page's text."""
    lines = [
        "# robocal's file formats",
        "",
        "Generated by `python -m robocal.server.formats.formats_doc` from the readers' column "
        "names and bounds and from the JSON Schemas; a test keeps this page equal to them. "
        "Units: mm and degrees in every file. CSV files are UTF-8 with a header row; columns "
        "may come in any order; a mistake is reported as file:line:column and the column name.",
        "",
        "Effects of a diagnosis are numbered from 1 in the report's order (most important "
        "first), the same number in `robocal diagnose`'s output, report.json and the figure "
        "files. Joints are numbered from 1 (q1 is the base joint).",
        "",
        "## CSV files",
        "",
        f"`{JOINTS}` stands for one column per joint of the cell's robot (q1 to q6 for a "
        "six-axis arm).",
        "",
    ]
    for f in CSV_FILES:
        lines += csv_section(f)
    lines += ["## JSON files", ""]
    for name in MODELS:
        lines += json_section(name)
    return "\n".join(lines).rstrip() + "\n"


if __name__ == "__main__":
    PAGE.parent.mkdir(exist_ok=True)
    PAGE.write_text(generated(), encoding="utf-8")
    print(f"wrote {PAGE}")
