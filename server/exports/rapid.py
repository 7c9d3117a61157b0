"""A RAPID module of joint targets (ABB), moved to in order with MoveAbsJ, and its reader."""

from __future__ import annotations

import re
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

AXES = 6  # a jointtarget's robax: rax_1 ... rax_6
DECIMALS = 5  # RAPID's num is single precision: 7 significant digits, 1e-5 deg at 100 deg
LINE_MAX = 80  # what the FlexPendant's editor shows without scrolling
NAME_MAX = 32  # RAPID identifiers: a letter, then letters, digits or '_', at most 32
NO_AXIS = "9E9"  # an external axis that is not there
# v100 spelled out (TCP mm/s, reorientation deg/s, external mm/s and deg/s): a CONST may not be
# initialised from another data object on every RobotWare
SPEED = "[100, 500, 5000, 1000]"
RESERVED = set(
    """ALIAS AND BACKWARD CASE CONNECT CONST DEFAULT DIV DO ELSE ELSEIF ENDFOR ENDFUNC ENDIF
    ENDMODULE ENDPROC ENDRECORD ENDTEST ENDTRAP ENDWHILE ERROR EXIT FALSE FOR FROM FUNC GOTO IF
    INOUT LOCAL MOD MODULE NOSTEPIN NOT NOVIEW OR PERS PROC RAISE READONLY RECORD RETRY RETURN
    STEP SYSMODULE TEST THEN TO TRAP TRUE TRYNEXT UNDO VAR VIEWONLY WHILE WITH XOR""".split()
)


def identifier(text: str, prefix: str = "M_") -> str:
    """A valid RAPID name made from text: other characters become '_', at most 32 long."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", text)
    if not name[:1].isalpha():
        name = prefix + name
    name = name[:NAME_MAX]
    return name[: NAME_MAX - 1] + "_" if name.upper() in RESERVED else name


def _unique(base: str, used: set[str]) -> str:
    """base, or base with _2, _3 ... (truncated to fit): RAPID names ignore case."""
    name, k = base, 1
    while name.lower() in used:
        k += 1
        suffix = f"_{k}"
        name = base[: NAME_MAX - len(suffix)] + suffix
    used.add(name.lower())
    return name


def _ascii(text: str) -> str:
    # a module is ASCII (ISO 8859-1 at most): other characters as \u escapes
    return text.encode("ascii", "backslashreplace").decode("ascii")


def _comment(text: str, indent: str = "    ") -> list[str]:
    return textwrap.wrap(
        _ascii(text),
        LINE_MAX,
        initial_indent=indent + "! ",
        subsequent_indent=indent + "! ",
        break_long_words=True,
        break_on_hyphens=False,
    )


def _num(v: float) -> str:
    return format(round(float(v), DECIMALS) + 0.0, f".{DECIMALS}f")


def module_text(
    module: str,
    pose_ids: list[str],
    q_deg: np.ndarray,
    predicted_error_mm: np.ndarray | None = None,
    about: Sequence[str] = (),
) -> str:
    """The module: one CONST jointtarget per pose (named after it), and a PROC that moves to
    each in the given order with MoveAbsJ, fine, tool0. `about`: header sentences."""
    q_deg = np.asarray(q_deg, dtype=float)
    if q_deg.ndim != 2 or q_deg.shape[1] != AXES:
        raise ValueError(
            f"a RAPID jointtarget holds {AXES} robot axes; these commands have {q_deg.shape[-1]}"
        )
    module = identifier(module)
    proc = identifier(f"Run_{module}")
    used = {module.lower(), proc.lower(), "rc_speed"}
    names = [_unique(identifier(f"jt_{pid}"), used) for pid in pose_ids]
    lines = [f"MODULE {module}"]
    for sentence in about:
        lines += _comment(sentence)
    lines += _comment(
        f"Run: load into the motion task (T_ROB1) and call {proc}, or set the program "
        f"pointer to it. Move at reduced speed first; RC_SPEED is v100."
    )
    lines += _comment(
        "robax in degrees; RAPID keeps about 7 significant digits (1E-5 deg at 100 deg). "
        f"{NO_AXIS}: no external axis."
    )
    lines += ["", f"    LOCAL CONST speeddata RC_SPEED := {SPEED};", ""]
    extax = ", ".join([NO_AXIS] * AXES)
    for k, (pid, name) in enumerate(zip(pose_ids, names)):
        note = f"pose {pid!r}"
        if predicted_error_mm is not None and np.isfinite(predicted_error_mm[k]):
            note += f", predicted error {predicted_error_mm[k]:.4f} mm"
        lines += _comment(note)
        lines.append(f"    LOCAL CONST jointtarget {name} :=")
        values = [_num(v) for v in q_deg[k]]
        robax = f"        [[{', '.join(values)}],"
        if len(robax) > LINE_MAX:  # a statement goes on over lines wherever a space may stand
            half = AXES // 2
            robax = f"        [[{', '.join(values[:half])},\n        {', '.join(values[half:])}],"
        lines += [*robax.split("\n"), f"        [{extax}]];"]
    lines += ["", f"    PROC {proc}()"]
    lines += [f"        MoveAbsJ {name}, RC_SPEED, fine, tool0;" for name in names]
    lines += ["    ENDPROC", "ENDMODULE", ""]
    return "\n".join(lines)


@dataclass(frozen=True)
class Module:
    """What a module says: its name, its joint targets by name, and the PROCs' moves in order."""

    name: str
    targets: dict[str, tuple[np.ndarray, np.ndarray]]  # name -> (robax, extax), degrees
    moves: list[str]  # jointtarget names, in the order the PROCs move to them


def _code(text: str) -> str:
    """The text with string literals emptied and comments dropped."""
    out = []
    for line in text.splitlines():
        line = re.sub(r'"(?:[^"]|"")*"', '""', line)
        out.append(line.split("!", 1)[0])
    return "\n".join(out)


_TARGET = re.compile(
    r"(?:LOCAL\s+|TASK\s+)?(?:CONST|PERS|VAR)\s+jointtarget\s+([A-Za-z]\w*)\s*:=\s*"
    r"\[\s*\[([^\[\]]*)\]\s*,\s*\[([^\[\]]*)\]\s*\]\s*$",
    re.IGNORECASE,
)
_MOVE = re.compile(r"MoveAbsJ\s+(?:\\Conc\s*,\s*)?([A-Za-z]\w*)\s*,", re.IGNORECASE)


def read_module(text: str) -> Module:
    """Read a module of jointtargets back (the form module_text writes); ValueError if it is
    not one."""
    code = _code(text)
    m = re.match(r"\s*MODULE\s+([A-Za-z]\w*)(.*)\bENDMODULE\s*$", code, re.S | re.I)
    if not m:
        raise ValueError("not a RAPID module (MODULE name ... ENDMODULE)")
    targets: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    moves: list[str] = []
    for statement in m.group(2).split(";"):
        s = " ".join(statement.split())
        t = _TARGET.match(s)
        if t:
            robax = np.array([float(v) for v in t.group(2).split(",")])
            extax = np.array([float(v) for v in t.group(3).split(",")])
            if len(robax) != AXES or len(extax) != AXES:
                raise ValueError(f"jointtarget {t.group(1)}: expected 6 robot and 6 external axes")
            targets[t.group(1)] = (robax, extax)
        mv = _MOVE.search(s)
        if mv:
            if mv.group(1) not in targets:
                raise ValueError(f"MoveAbsJ to {mv.group(1)}, which the module does not define")
            moves.append(mv.group(1))
    return Module(m.group(1), targets, moves)
