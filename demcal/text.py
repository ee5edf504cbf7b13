"""Text from the workbook on its way out: one safe line.

Workbook text (a material name, an id, a covariate) is untrusted. It reaches a terminal, a
LIGGGHTS or Yade input file, a CSV, a figure label. :func:`one_line` is the one reduction they
all use: no line break, no control character, bounded length. :func:`control_characters` is what
``measure`` refuses in a cell.
"""

from __future__ import annotations

import unicodedata

#: Longest text kept by :func:`one_line` by default [characters].
MAX_LINE = 200

#: First characters that make a spreadsheet run a cell as a formula (tab and carriage return,
#: the others of that kind, never survive :func:`one_line`).
FORMULA_START = ("=", "+", "-", "@")

#: Unicode categories that may end a line or move the cursor: controls (Cc, which holds
#: \\n, \\r, \\t, ESC, NEL), format characters (Cf: bidi overrides), line and paragraph
#: separators (Zl, Zp), and unassigned or private code points.
_UNSAFE_CATEGORIES = frozenset({"Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn"})


def _unsafe(ch: str) -> bool:
    return unicodedata.category(ch) in _UNSAFE_CATEGORIES


def control_characters(text: str) -> list[str]:
    """The unsafe characters of ``text``, as escapes (e.g. ``['\\\\n']``), in order, once each."""
    seen: list[str] = []
    for ch in str(text):
        if _unsafe(ch):
            esc = ch.encode("unicode_escape").decode("ascii")
            if esc not in seen:
                seen.append(esc)
    return seen


def one_line(text, *, limit: int = MAX_LINE, replacement: str = " ") -> str:
    """``text`` as one printable line: every control, format or separator character is replaced
    by ``replacement``, runs of white space collapse to one space, and text longer than
    ``limit`` characters is cut with an ellipsis.

    The result holds no character that ends a line in a terminal, a Python or LIGGGHTS input
    file or a CSV record.
    """
    cleaned = "".join(replacement if _unsafe(ch) else ch for ch in str(text))
    cleaned = " ".join(cleaned.split())
    if len(cleaned) > limit:
        cleaned = cleaned[: max(limit - 1, 0)] + "\u2026"
    return cleaned


def no_formula(cell: str) -> str:
    """A CSV cell of text that a spreadsheet shows as text: a leading ``'`` where it would
    otherwise run the cell as a formula (CSV injection)."""
    return "'" + cell if cell.startswith(FORMULA_START) else cell
