"""What an input value may be: the instrument's range, joint angles, sizes, and clean text.

Every number a user file or request brings is checked against these at parse time, so that no
finite-but-absurd value (x = 1e308) reaches the numerics, where it would overflow to inf.
"""

from __future__ import annotations

import unicodedata

# A laser tracker measures out to about 80 m (Leica AT960: 80 m radius); 100 m is beyond any
# instrument, and every distance in a cell (SMR positions, base, link lengths) is shorter.
COORD_MAX_MM = 100_000.0
# Three full turns: beyond the widest joint ranges sold (+-720 deg on some wrist axes).
ANGLE_MAX_DEG = 1080.0
# A cell's SMRs: a handful on a flange fixture (three fix the flange's pose). Planning and
# calibration carry three parameters per SMR, so every count beyond this only costs.
SMRS_MAX = 16
# Joints of a serial arm: the kinematics handles any chain, and the arms sold have up to seven
# axes (a redundant arm); the ABB controller protocol drives at most six (drivers.abb.protocol).
JOINTS_MAX = 7
# A link's length a and offset d: the largest arms sold reach under 5 m in all.
LINK_MAX_MM = 5_000.0
# The links of an arm add up (sum of sqrt(a^2 + d^2)) to at least this: below it the table is
# degenerate (all zeros) or given in metres.
REACH_MIN_MM = 100.0
# Seconds since a campaign's start: 30 years.
TIME_MAX_S = 1e9
# Air temperature at a tracker's weather station.
TEMP_RANGE_C = (-100.0, 200.0)
# Any other number of a JSON document (tracker spec, payload, model coefficients): sane and far
# from overflow whatever it is multiplied by.
NUMBER_MAX = 1e12
# A meas.csv of 5,000 poses with 50 SMRs; the file itself (a row is ~100 bytes).
CSV_ROWS_MAX = 250_000
FILE_BYTES_MAX = 64 * 1024 * 1024
# Pose ids and names: a label, not a document.
LABEL_CHARS_MAX = 200
# A name or label: printable, no control characters (NUL, newline, escape, DEL, U+2028/9), so
# that it cannot break a CSV row, a log line or a terminal; bad_text's rule as a pattern.
_CTRL = r"\x00-\x1f\x7f-\x9f\u2028\u2029"
PRINTABLE = rf"^[^{_CTRL}]*[^\s{_CTRL}][^{_CTRL}]*$"  # and not blank


def bad_text(text: str) -> str | None:
    """Why this label cannot be stored (control characters, NUL, too long), or None if it can."""
    if len(text) > LABEL_CHARS_MAX:
        return f"is {len(text)} characters long, at most {LABEL_CHARS_MAX} are allowed"
    for i, ch in enumerate(text):
        # Cc: NUL, tab, newline, escape, DEL...; Zl/Zp: line and paragraph separators. Any of
        # them would break a CSV row, a log line or a terminal showing the name.
        if unicodedata.category(ch) in ("Cc", "Zl", "Zp"):
            return f"contains the control character U+{ord(ch):04X} at position {i + 1}"
    return None


def out_of_range(value: float, bound: float) -> bool:
    """Whether |value| exceeds bound."""
    return not -bound <= value <= bound
