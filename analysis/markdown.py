"""Markdown pieces shared by the reports: tables, estimates with intervals, file names.

pandas writes Markdown only through the optional ``tabulate`` package, which evo does
not depend on; :func:`markdown_table` is the few lines needed for GitHub pipe tables.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd


def fmt_number(value: object, digits: int = 3) -> str:
    """A cell: floats to ``digits`` significant decimals, NaN/None as an en dash."""
    if value is None or (isinstance(value, float | np.floating) and math.isnan(value)):
        return "–"
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, float | np.floating):
        return f"{value:.{digits}f}"
    return str(value)


def fmt_ci(estimate: float, low: float, high: float, digits: int = 3) -> str:
    """``estimate [low, high]``; the interval left out when it is undefined."""
    text = fmt_number(estimate, digits)
    if math.isnan(low) or math.isnan(high):
        return text
    return f"{text} [{fmt_number(low, digits)}, {fmt_number(high, digits)}]"


def markdown_table(table: pd.DataFrame, digits: int = 3, index: bool = False) -> str:
    """A GitHub pipe table of ``table`` (numbers right-aligned).

    Args:
        table: The table.
        digits: Decimals of float cells.
        index: Whether to write the index as the first column.

    Returns:
        The Markdown text, ending in a newline; ``_(empty)_`` for an empty table.
    """
    if index:
        table = table.reset_index()
    if table.empty:
        return "_(empty)_\n"
    header = [str(c) for c in table.columns]
    numeric = [pd.api.types.is_numeric_dtype(table[c]) and not pd.api.types.is_bool_dtype(
        table[c]) for c in table.columns]
    rule = ["---:" if n else "---" for n in numeric]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(rule) + " |"]
    for row in table.itertuples(index=False):
        cells = [fmt_number(v, digits).replace("|", "\\|") for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def safe_name(text: str) -> str:
    """``text`` as a file-name part: characters other than letters, digits, ``+-_.``
    become ``_``."""
    return re.sub(r"[^A-Za-z0-9+_.-]", "_", text)


def figure_link(path: Path, out: Path, caption: str) -> str:
    """A Markdown image of ``path`` relative to the report folder ``out``."""
    return f"![{caption}]({path.relative_to(out).as_posix()})\n"
