"""Notebooks are documents: parameters, one call per table, the table, the figure and prose. The
logic lives in greenloop/experiments/, where the unit tests reach it."""
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))
MAX_CODE_LINES = 120


def code_lines(nb: dict) -> list[str]:
    """The code cells' lines that are neither blank nor comments."""
    lines = [line for c in nb["cells"] if c["cell_type"] == "code"
             for line in "".join(c["source"]).splitlines()]
    return [line for line in lines if line.strip() and not line.strip().startswith("#")]


def definitions(lines) -> list[str]:
    """Lines that define a function, a class or a lambda bound to a name."""
    return [line for line in lines if re.match(r"\s*(async\s+)?(def|class)\s", line)
            or re.match(r"\s*\w+\s*=\s*lambda\b", line)]


def test_definitions_finds_defs_classes_and_named_lambdas():
    nb = {"cells": [{"cell_type": "code", "source": ["x = 1\n", "# def not_this()\n", "def f(a):\n", "    return a\n"]},
                    {"cell_type": "markdown", "source": ["def in prose\n"]},
                    {"cell_type": "code", "source": ["class K:\n", "  pass\n", "g = lambda v: v\n", "sorted(x, key=lambda v: v)\n"]}]}
    lines = code_lines(nb)
    assert len(lines) == 7
    assert definitions(lines) == ["def f(a):", "class K:", "g = lambda v: v"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_defines_nothing_and_stays_short(path):
    lines = code_lines(json.loads(path.read_text()))
    assert not definitions(lines), f"{path.name} defines {definitions(lines)}: move it to greenloop/experiments/"
    assert len(lines) <= MAX_CODE_LINES, f"{path.name} has {len(lines)} code lines (at most {MAX_CODE_LINES})"
