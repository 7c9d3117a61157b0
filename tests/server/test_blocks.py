"""The result blocks cross layers typed: no module of the server reads a block (fit, uncertainty,
identified, validation, diagnosis, unexplained, accuracy) by its string key, and no verdict is
read with a default; model.json and report.json, as written, are the documents of
formats.blocks."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BLOCKS = {"fit", "identified", "validation", "diagnosis", "unexplained", "accuracy"}
# `uncertainty` names other things too (an effect's, a verification's): banned off a model's meta
META_BLOCKS = BLOCKS | {"uncertainty"}
# formats/ defines the documents and reads and writes their files
EXEMPT = ("server/formats/",)


def _key(node: ast.AST) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def _off_meta(node: ast.AST) -> bool:
    """Whether the expression is `<something>.meta` or a name `meta`."""
    return (isinstance(node, ast.Attribute) and node.attr == "meta") or (
        isinstance(node, ast.Name) and node.id == "meta"
    )


def string_key_reads(source: str) -> list[tuple[int, str]]:
    """(line, key) of each read of a result block by string key: x["fit"], x.get("fit"),
    "fit" in x (writes, x["fit"] = ..., are not reads); and each `.get("deployable", ...)`."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Subscript) and isinstance(node.ctx, (ast.Load, ast.Del)):
            key = _key(node.slice)
            if key in BLOCKS or (key in META_BLOCKS and _off_meta(node.value)):
                out.append((node.lineno, key))
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in ("get", "setdefault", "pop")
            and node.args
        ):
            key = _key(node.args[0])
            owner = node.func.value
            if key in BLOCKS or (key in META_BLOCKS and _off_meta(owner)):
                out.append((node.lineno, key))
            elif key == "deployable" and len(node.args) + len(node.keywords) > 1:
                out.append((node.lineno, "deployable with a default"))
        elif isinstance(node, ast.Compare) and any(
            isinstance(op, (ast.In, ast.NotIn)) for op in node.ops
        ):
            key = _key(node.left)
            if key in BLOCKS or (key in META_BLOCKS and any(map(_off_meta, node.comparators))):
                out.append((node.lineno, key))
    return out


# The ISO 9283 figures of a verification (formats.verification_doc) are read as attributes only
VERIFICATION_FIGURES = {"AP_max_mm", "RP_max_mm", "AP_mm", "RP_mm", "vAP_mm", "AP_U_mm", "AD_mm"}
VERIFICATION_FIGURES |= {"RD_mm"}
# The keys only an excluded reading's row has (solver.screen.Outlier, formats.report_doc.Outlier)
OUTLIER_KEYS = {"residual_mm", "evidence"}
# The keys of a diagnosis figure's data (solver.diagnosis_report.EffectFigure)
FIGURE_KEYS = {"label", "x_label", "y_label", "expected"}
# An acquisition's result (acquisition.summary.AcquireSummary), read off `summary`, `acquired`,
# `x.summary`: its fields' names (other summaries, a benchmark's, have other keys)
ACQUIRE_KEYS = {"campaign", "name", "resumed_at", "poses", "state", "measured_poses"}
ACQUIRE_KEYS |= {"readings", "missing", "beam_breaks", "campaign_s", "phase_s", "adaptive"}
ACQUIRE_KEYS |= {"locked_without_search_after_10", "simulated", "skipped_poses", "searched"}


def _acquired(node: ast.AST) -> bool:
    """Whether the expression names an acquisition's summary."""
    name = node.id if isinstance(node, ast.Name) else getattr(node, "attr", None)
    return name in ("summary", "acquired")


def _owner(node: ast.AST) -> str | None:
    """Which typed result an expression names: a report (`report`, `x.report`: a diagnosis's
    formats.report_doc.ReportDoc or a verification's VerificationDoc) or a calibration (`cal`,
    `calibration`: solver.calibrate.Calibration, read by attribute)."""
    name = node.id if isinstance(node, ast.Name) else getattr(node, "attr", None)
    if name == "report":
        return "a report"
    if name in ("cal", "calibration"):
        return "a calibration"
    return None


def _keyed(tree: ast.AST):
    """(line, key, owner) of each read by string key in tree: x["k"], x.get("k"), "k" in x."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and isinstance(node.ctx, (ast.Load, ast.Del)):
            key, owner = _key(node.slice), node.value
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in ("get", "setdefault", "pop")
            and node.args
        ):
            key, owner = _key(node.args[0]), node.func.value
        elif isinstance(node, ast.Compare) and isinstance(node.ops[0], (ast.In, ast.NotIn)):
            key, owner = _key(node.left), node.comparators[0]
        else:
            continue
        if key is not None:
            yield node.lineno, key, owner


def result_key_reads(source: str) -> list[tuple[int, str]]:
    """(line, what) of each read by string key of a diagnosis or verification report (any key
    off `report` or `x.report`), of a calibration (any key off `cal`), of a verification's
    figures (AP_mm, RP_max_mm... off anything), of an excluded reading's row (residual_mm,
    evidence off anything), of a diagnosis figure's data (label, x_label... off anything) or of
    an acquisition's summary (its fields off `summary`, `acquired`): x["k"], x.get("k"), "k" in x."""
    out = []
    for line, key, owner in _keyed(ast.parse(source)):
        what = _owner(owner) or (
            "a verification"
            if key in VERIFICATION_FIGURES
            else "an outlier"
            if key in OUTLIER_KEYS
            else "a figure"
            if key in FIGURE_KEYS
            else "an acquisition"
            if key in ACQUIRE_KEYS and _acquired(owner)
            else None
        )
        if what:
            out.append((line, f"{key!r} of {what}"))
    return sorted(out)


# An adaptive campaign's summary (acquisition.adaptive_plan.AdaptiveSummary: off `adaptive`,
# `x.adaptive`, `x["adaptive"]` or a name bound to one) and its steps (Step: off `step`, an item
# of `steps`, `x.steps`, `x["steps"]`, or a name a loop binds over them); `predicted_mm` off
# anything. Stored steps (the settings' `adaptive_steps`, events) are JSON, read where stored.
ADAPTIVE_KEYS = {"target_accuracy_mm", "steps", "stopped", "message", "predicted_mm"}
STEP_KEYS = {"poses", "predicted_mm", "floor_mm", "parameters_mm", "holdout_mm", "stop"}
STEP_KEYS |= {"expected_holdout_mm", "kappa", "reason", "message", "campaign_s", "effects"}
STEP_KEYS |= {"named", "extensions"}


def _named(node: ast.AST, name: str) -> bool:
    """Whether the expression is `name`, `x.name` or `x["name"]`."""
    if isinstance(node, ast.Subscript):
        return _key(node.slice) == name
    return (node.id if isinstance(node, ast.Name) else getattr(node, "attr", None)) == name


def adaptive_key_reads(source: str) -> list[tuple[int, str]]:
    """(line, what) of each read by string key of an adaptive campaign's summary or step."""
    tree = ast.parse(source)
    summaries, steps = set(), {"step"}  # names bound to a summary, to a step
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and _named(node.value, "adaptive"):
            summaries |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, (ast.For, ast.comprehension)) and _named(node.iter, "steps"):
            steps |= {node.target.id} if isinstance(node.target, ast.Name) else set()

    def summary(node):
        return _named(node, "adaptive") or (isinstance(node, ast.Name) and node.id in summaries)

    def step(node):
        if isinstance(node, ast.Subscript) and _key(node.slice) is None:
            return _named(node.value, "steps")  # steps[-1]
        return isinstance(node, ast.Name) and node.id in steps

    out = []
    for line, key, owner in _keyed(tree):
        if key == "predicted_mm" or (key in ADAPTIVE_KEYS and summary(owner)):
            out.append((line, f"{key!r} of an adaptive summary"))
        elif key in STEP_KEYS and step(owner):
            out.append((line, f"{key!r} of an adaptive step"))
    return sorted(out)


def test_the_adaptive_check_finds_the_summary_and_its_steps_read_by_key():
    src = (  # as the server read them before they were typed
        'a = s.adaptive\nif a["steps"]:\n    e = a["steps"][-1].get("extensions") or ()\n'
        'x = r["adaptive"]["stopped"]\nsteps = r["adaptive"]["steps"]\n'
        'y = [(s["poses"], s["predicted_mm"]) for s in steps]\nz = steps[-1].get("effects")\n'
        'w = ", ".join(s["poses"] for s in adaptive["steps"])\nv = adaptive["message"]\n'
        'if self.steps and self.steps[-1]["poses"] == step["poses"]:\n    pass\n'
        'ok = [a.steps, info.settings["adaptive_steps"], row["poses"], x["stopped"]]\n'
    )
    assert adaptive_key_reads(src) == [
        (2, "'steps' of an adaptive summary"),
        (3, "'extensions' of an adaptive step"),
        (3, "'steps' of an adaptive summary"),
        (4, "'stopped' of an adaptive summary"),
        (5, "'steps' of an adaptive summary"),
        (6, "'poses' of an adaptive step"),
        (6, "'predicted_mm' of an adaptive summary"),
        (7, "'effects' of an adaptive step"),
        (8, "'poses' of an adaptive step"),
        (8, "'steps' of an adaptive summary"),
        (9, "'message' of an adaptive summary"),
        (10, "'poses' of an adaptive step"),
        (10, "'poses' of an adaptive step"),
    ]


def test_no_adaptive_summary_or_step_is_read_by_string_key_outside_the_formats():
    found = reads_outside_the_formats(adaptive_key_reads)
    assert not found, (
        "read the typed summary (acquisition.adaptive_plan.AdaptiveSummary, Step) instead:\n"
        + "\n".join(found)
    )


def test_the_result_check_finds_reports_calibrations_and_figures_read_by_key():
    src = (  # as the server read them before they were typed
        'a = d.report["effects"]\nb = report["before"]["points"]\nc = cal.get("screening")\n'
        'e = "history" in cal\nf = p["AP_mm"]\ng = report.get("uncertainty") or {}\n'
        'h = calibration.get("history")\nreport["figures"] = []\ni = row["name"]\n'
        "j = f\"{o['residual_mm']:.3f} ({o['evidence']})\"\n"
        'k = {f["label"]: p for f, p in z}\nax.set_xlabel(series["x_label"])\n'
        'if summary["state"] != "done":\n    c = run.summary["campaign"]\n'
        'l = acquired["campaign_s"]\nm = summary["detection"]\n'
    )
    assert result_key_reads(src) == [
        (1, "'effects' of a report"),
        (2, "'before' of a report"),
        (3, "'screening' of a calibration"),
        (4, "'history' of a calibration"),
        (5, "'AP_mm' of a verification"),
        (6, "'uncertainty' of a report"),
        (7, "'history' of a calibration"),
        (10, "'evidence' of an outlier"),
        (10, "'residual_mm' of an outlier"),
        (11, "'label' of a figure"),
        (12, "'x_label' of a figure"),
        (13, "'state' of an acquisition"),
        (14, "'campaign' of an acquisition"),
        (15, "'campaign_s' of an acquisition"),
    ]


def reads_outside_the_formats(check) -> list[str]:
    """Each read check(source) finds in the server outside formats/, as path:line and what."""
    found = []
    for path in sorted((ROOT / "server").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if not rel.startswith(EXEMPT):
            found += [
                f"{rel}:{line} reads {what} by string key" for line, what in check(path.read_text())
            ]
    return found


def test_no_report_calibration_or_verification_is_read_by_string_key_outside_the_formats():
    found = reads_outside_the_formats(result_key_reads)
    assert not found, (
        "read the typed result (formats.report_doc, formats.verification_doc, Calibration's "
        "attributes) instead:\n" + "\n".join(found)
    )


def test_the_check_finds_each_kind_of_read():
    src = (
        'a = m.meta["validation"]\nb = r.get("identified")\nc = "fit" in report\n'
        'd = meta.get("uncertainty")\ne = v.get("deployable", True)\nm.meta["fit"] = 1\n'
        'f = e.get("uncertainty")\n'
    )
    assert string_key_reads(src) == [
        (1, "validation"),
        (2, "identified"),
        (3, "fit"),
        (4, "uncertainty"),
        (5, "deployable with a default"),
    ]


def test_no_result_block_is_read_by_string_key_outside_the_formats():
    found = reads_outside_the_formats(lambda src: [(n, repr(k)) for n, k in string_key_reads(src)])
    assert not found, "read the typed block (formats.blocks) instead:\n" + "\n".join(found)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A calibration's and a diagnosis's model.json and the diagnosis's report.json, as the
    commands write them."""
    from robocal.drivers.cell import VirtualCell
    from robocal.server.calibration import workflow
    from robocal.server.formats.cell_json import default_cell
    from robocal.server.formats.model_json import write_model

    d = tmp_path_factory.mktemp("blocks")
    cell = default_cell()
    meas = VirtualCell.random(cell.robot, cell.targets, seed=5).campaign(40, seed=5)
    cal = workflow.run_method(cell, meas, "ls-sum")
    write_model(d / "cal.json", workflow.model_file(cal, cell, meas))
    diagnosis, model = workflow.diagnose(cell, meas, screen=False)
    workflow.write_diagnosis(diagnosis, model, d / "report.json", {"poses": 40}, d / "diag.json")
    return d


@pytest.mark.parametrize("name", ["cal.json", "diag.json"])
def test_model_json_is_its_document_and_reads_back_the_same(written, name):
    from robocal.server.formats.blocks import Block
    from robocal.server.formats.model_doc import ModelDoc
    from robocal.server.formats.model_json import model_to_json, read_model

    text = json.loads((written / name).read_text())
    doc = ModelDoc.model_validate(text)
    for key in ("fit", "uncertainty", "identified", "validation", "diagnosis"):
        block = getattr(doc, key)
        assert (block is None) == (key not in text), key
        if block is not None:
            assert isinstance(block, Block) and block.to_json() == text[key], key
    back = model_to_json(read_model(written / name))
    assert {k: v for k, v in back.items() if k != "created"} == {
        k: v for k, v in text.items() if k != "created"
    }
    assert list(back) == list(text)  # the keys in the order written


def test_report_json_is_its_document(written):
    from robocal.server.formats.report_doc import ReportDoc

    text = json.loads((written / "report.json").read_text())
    doc = ReportDoc.model_validate(text)
    assert doc.validation is not None and doc.identified is not None
    assert doc.validation.to_json() == text["validation"]
    assert doc.identified.to_json() == text["identified"]
    assert doc.final.to_json() == text["final"]


# The solver's report fields that stay maps: a phase's seconds by its name, an effect kind's own
# keys and its parameters by their names (each kind has its own); `unexplained` is still a dict
MAPS = {"seconds", "own", "parameters", "uncertainty", "unexplained"}


def test_the_solver_report_nests_typed_blocks():
    """Each nested block of the solver's report (outliers, extrapolation, stability,
    significance, alternatives, cross-validation) is a dataclass, not a dict read by key."""
    from dataclasses import fields

    from robocal.solver.diagnosis_report import Finding, Report

    untyped = [
        f"{cls.__name__}.{f.name}: {f.type}"
        for cls in (Report, Finding)
        for f in fields(cls)
        if "dict" in str(f.type) and f.name not in MAPS
    ]
    assert not untyped, "give these blocks a dataclass (solver/report_blocks.py):\n" + "\n".join(
        untyped
    )
