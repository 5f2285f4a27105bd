"""Notebooks are documents: parameters, one call per table, the table, the figure and prose. The
logic lives in greenloop/experiments/, where the unit tests reach it."""
import ast
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


def parameter_names(nb: dict) -> set[str]:
    """The names the cell tagged ``parameters`` assigns."""
    cell = next(c for c in nb["cells"] if "parameters" in c.get("metadata", {}).get("tags", []))
    return {t.id for node in ast.parse("".join(cell["source"])).body if isinstance(node, (ast.Assign, ast.AnnAssign))
            for t in (node.targets if isinstance(node, ast.Assign) else [node.target]) if isinstance(t, ast.Name)}


def _is(node, dotted: str) -> bool:
    """Whether a call's function is ``dotted`` (``report.manifest``, ``dict``)."""
    return isinstance(node, ast.Call) and ast.unparse(node.func) == dotted


def retyped(nb: dict) -> list[str]:
    """Parameters typed a second time where the run records them: each ``report.manifest`` call whose
    parameters are not ``report.parameters(globals(), ...)``, and, within a ``report.manifest`` or a
    ``report.parameters`` call, each ``name=name`` keyword and each literal dict entry (``dict(name=name)``,
    ``{"name": name}``) that repeats a parameter of the notebook's parameters cell by its own name (a
    parameter is there already). A dict of arguments for a function (notebook 10's ``TRAIN_KW``) or a
    summary.json entry is no record of the parameters and is not looked at."""
    names, found = parameter_names(nb), []
    for c in nb["cells"]:
        if c["cell_type"] != "code" or "parameters" in c.get("metadata", {}).get("tags", []):
            continue
        for call in ast.walk(ast.parse("".join(c["source"]))):
            if not (_is(call, "report.manifest") or _is(call, "report.parameters")):
                continue
            if _is(call, "report.manifest"):
                given = call.args[1] if len(call.args) > 1 else next((k.value for k in call.keywords if k.arg == "parameters"), None)
                if not (_is(given, "report.parameters") and given.args and _is(given.args[0], "globals")):
                    found.append(f"report.manifest({ast.unparse(given) if given else ''}, ...) does not take report.parameters(globals())")
            for node in ast.walk(call):
                pairs = []
                if node is call or _is(node, "dict"):     # report.manifest's dataset= is its own argument
                    pairs = [(k.arg, k.value) for k in node.keywords if k.arg and not (node is call and k.arg == "dataset")]
                elif isinstance(node, ast.Dict):
                    pairs = [(k.value, v) for k, v in zip(node.keys, node.values) if isinstance(k, ast.Constant)]
                found += [f"{k}={k}" for k, v in pairs if k in names and isinstance(v, ast.Name) and v.id == k]
    return found


def test_retyped_finds_parameters_typed_twice():
    nb = {"cells": [{"cell_type": "code", "metadata": {"tags": ["parameters"]}, "source": ["dataset = 'd'\n", "epochs = 3\n", "seeds = [0]\n"]},
                    {"cell_type": "code", "metadata": {}, "source": [
                        "kw = dict(epochs=epochs, n=len(seeds))\n", "s = {'seeds': seeds}\n",     # arguments, a summary: not records
                        "report.manifest(OUT, report.parameters(globals(), epochs=epochs, used=seeds[:1]))\n",
                        "report.manifest(OUT, dict(n=1, seeds=seeds), dataset=dataset, info={'epochs': epochs})\n"]}]}
    assert sorted(retyped(nb)) == ["epochs=epochs", "epochs=epochs", "report.manifest(dict(n=1, seeds=seeds), ...) does not "
                                   "take report.parameters(globals())", "seeds=seeds"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_states_its_parameters_once(path):
    """The parameters cell is the notebook's first code cell (report.parameters' reading where papermill
    injected nothing), and the manifest takes the parameters as the run set them (report.parameters):
    no dict repeats them."""
    nb = json.loads(path.read_text())
    first = next(c for c in nb["cells"] if c["cell_type"] == "code")
    assert "parameters" in first["metadata"].get("tags", []), f"{path.name}: the first code cell is not tagged parameters"
    assert "report.parameters(globals()" in "".join("".join(c["source"]) for c in nb["cells"])
    assert not retyped(nb), f"{path.name} types its parameters again: {retyped(nb)}"
