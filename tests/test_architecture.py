"""greenloop.architecture: the package holds its layer contract (no import up a layer, no cycle, no
import inside a function), the checker reports a planted violation of each kind, and
docs/ARCHITECTURE.md lists the contract's layers as they are.

(tests/test_layers.py is features.layers' test: CNN layers, not these.)"""
import re
from pathlib import Path

import pytest

import greenloop
from greenloop import architecture
from greenloop.architecture import Layer
from greenloop.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = Path(greenloop.__file__).resolve().parent


def test_the_package_holds_its_layers():
    assert architecture.check(PACKAGE) == []


def test_the_reader_sees_every_form_of_import():
    """Module level and function-local, ``from greenloop import x`` (a module), ``from greenloop.x
    import name`` (a name of a module): the imports the contract is checked on."""
    found = {(i.module, i.target): i for i in architecture.imports(PACKAGE)}
    assert ("greenloop.speed.bench", "greenloop.report") in found                 # from greenloop import report
    assert ("greenloop.experiments.default_choice", "greenloop.experiments.leaderboard") in found
    assert ("greenloop.cli.detect", "greenloop.methods.registry") in found       # from greenloop.methods import registry
    assert ("greenloop.__main__", "greenloop.cli") in found                   # from greenloop.cli import main
    assert not any(i.local for i in found.values())
    assert architecture.unit("greenloop.speed.bench") == "speed" and architecture.unit("greenloop") == "__init__"


DOORS = {"greenloop.methods.registry", "greenloop.methods.interface"}


def _reached(start: str, edges: dict) -> set:
    """Every module ``start`` imports, directly or through others (edges: {module: its targets})."""
    seen, todo = set(), [start]
    while todo:
        for t in edges.get(todo.pop(), ()):
            if t not in seen:
                seen.add(t)
                todo.append(t)
    return seen


def test_a_users_run_enters_methods_by_the_registry_only_and_never_runs_through_speed():
    """The registry is the only door: detect.py and cli/ import from methods/ only the registry and the interface
    (no method's internals), and a user's detect (greenloop.detect, greenloop.cli.detect) reaches
    nothing of speed/ (the measuring layer), directly or through what it imports."""
    found = architecture.imports(PACKAGE)
    users = [i for i in found if i.module == "greenloop.detect" or i.module.startswith("greenloop.cli")]
    inside = {(i.module, i.target) for i in users if i.target.startswith("greenloop.methods") and i.target not in DOORS}
    assert inside == set()
    assert {i.target for i in users if i.target.startswith("greenloop.methods")} == DOORS
    edges = {}
    for i in found:
        edges.setdefault(i.module, set()).add(i.target)
    for run in ("greenloop.detect", "greenloop.cli.detect"):
        assert not {m for m in _reached(run, edges) if m.startswith("greenloop.speed")}, run


def _package(tmp_path, files: dict) -> Path:
    root = tmp_path / "pkg"
    for name, text in {"__init__.py": "", "util/__init__.py": "", **files}.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return root


CONTRACT = (Layer("bottom", ("__init__", "util", "low"), "the bottom"), Layer("top", ("top",), "the top"))


def test_a_planted_upward_import_is_reported(tmp_path):
    clean = {"low.py": "from pkg.util import helpers\n", "util/helpers.py": "X = 1\n",
             "top.py": "from pkg import low\n"}
    assert architecture.check(_package(tmp_path / "clean", clean), CONTRACT) == []
    root = _package(tmp_path / "bad", {**clean, "util/helpers.py": "from pkg.top import T\nX = 1\n",
                                       "top.py": "T = 1\n"})
    problems = architecture.check(root, CONTRACT)
    assert len(problems) == 1 and "pkg/util/helpers.py:1" in problems[0]
    assert "pkg.util.helpers (layer 'bottom') imports pkg.top (layer 'top', higher)" in problems[0]


def test_a_hidden_relative_or_local_upward_import_is_reported(tmp_path):
    root = _package(tmp_path, {"low.py": "def f():\n    from . import top\n    return top\n",
                               "util/helpers.py": "from ..top import T\n", "top.py": "T = 1\n"})
    problems = architecture.check(root, CONTRACT)
    assert any("pkg/low.py:2" in p and "inside a function" in p for p in problems)
    assert any("pkg/low.py:2" in p and "an import up a layer" in p for p in problems)
    assert any("pkg/util/helpers.py:1: pkg.util.helpers (layer 'bottom') imports pkg.top" in p for p in problems)


def test_a_cycle_inside_one_layer_and_an_unplaced_module_are_reported(tmp_path):
    root = _package(tmp_path, {"low.py": "from pkg.util import helpers\n",
                               "util/helpers.py": "from pkg import low\n", "top.py": "", "new.py": ""})
    problems = architecture.check(root, CONTRACT)
    assert "import cycle among low, util" in problems
    assert "pkg.new is in no layer of the contract: place it in one" in problems
    gone = (Layer("bottom", ("__init__", "util", "low", "gone"), ""), Layer("top", ("top", "new"), ""))
    assert "the contract names 'gone', which is not in pkg/" in architecture.check(root, gone)


def test_a_cycle_between_modules_of_one_unit_is_reported(tmp_path):
    root = _package(tmp_path, {"low.py": "", "top.py": "", "util/a.py": "from pkg.util import b\n",
                               "util/b.py": "from pkg.util import a\n"})
    assert architecture.check(root, CONTRACT) == ["import cycle among the modules pkg.util.a, pkg.util.b"]


def test_the_documented_layers_are_the_contract():
    """docs/ARCHITECTURE.md's layer table is ``python -m greenloop layers --markdown``."""
    text = (ROOT / "docs" / "ARCHITECTURE.md").read_text()
    start, end = "<!-- layers:start (python -m greenloop layers --markdown) -->\n", "<!-- layers:end -->"
    assert start in text and end in text, "docs/ARCHITECTURE.md lost its layer table"
    assert text.split(start, 1)[1].split(end, 1)[0] == architecture.markdown(), (
        "docs/ARCHITECTURE.md's layer table is stale: paste `python -m greenloop layers --markdown`")


def test_command_line(capsys):
    assert cli_main(["layers"]) == 0 and "holds its" in capsys.readouterr().out
    assert cli_main(["layers", "--markdown"]) == 0 and capsys.readouterr().out == architecture.markdown()
    with pytest.raises(SystemExit):
        cli_main(["layers", "--bogus"])


def _layout_block() -> str:
    text = (ROOT / "docs" / "ARCHITECTURE.md").read_text()
    return re.search(r"## The layout.*?```\n(.*?)```", text, re.S).group(1)


def _layout_problems(block: str) -> list[str]:
    """Modules and folders of the package the layout block does not name, and names it gives that
    are no module of the package."""
    named = set(re.findall(r"([\w]+\.py)\b", block))
    folders = set(re.findall(r"([\w]+)/", block))
    files = [p.relative_to(PACKAGE) for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts]
    missing = {str(p) for p in files if p.name not in named and p.name != "__init__.py"}
    missing |= {f"{d}/" for p in files for d in p.parts[:-1] if d not in folders}
    extra = {f"no module {n}" for n in named if not any(p.name == n for p in files)}
    return sorted(missing | extra)


def test_the_documented_layout_is_the_package():
    """docs/ARCHITECTURE.md's layout names every module and folder of the package, and nothing else."""
    block = _layout_block()
    assert _layout_problems(block) == [], "docs/ARCHITECTURE.md's layout differs from the package"
    assert _layout_problems(block.replace("similarity.py", "similarities.py")) == ["no module similarities.py",
                                                                                     "similarity.py"]
    assert _layout_problems(block.replace("speed/", "speed")) == ["speed/"]
