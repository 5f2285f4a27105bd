"""The layer contract of the greenloop package, and the checker that holds the code to it.

``LAYERS`` lists the package's layers from the bottom to the top; each is a set of *units*: the
top-level modules and subpackages of ``greenloop/`` (``"util"`` is ``greenloop/util/``,
``"report"`` is ``greenloop/report.py``; ``"__init__"`` is the package's own ``__init__.py`` and
``"__main__"`` its command line). The rules:

1. a module imports greenloop only from its own layer or a lower one (never up);
2. there is no import cycle between units (inside one layer either), nor between the modules of
   one unit;
3. every import of greenloop stands at module level, none inside a function or class, so that a
   file's first lines say what it builds on;
4. every unit of the package is in exactly one layer, and every unit named here exists.

Imports are read from the source with ``ast`` (``import greenloop.x``, ``from greenloop import x``,
``from greenloop.x import y`` and relative forms, at module level and inside functions), so an
import that a function makes only when it runs is seen too.

``python -m greenloop layers`` checks the package (exit status 1 and one line per violation);
``--markdown`` prints the layer listing that docs/ARCHITECTURE.md holds (tests/test_architecture.py
compares the two).
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import NamedTuple


class Layer(NamedTuple):
    """name: a short name; units: the greenloop units in it; what: one line saying what they are."""
    name: str
    units: tuple[str, ...]
    what: str


LAYERS: tuple[Layer, ...] = (
    Layer("base", ("__init__", "architecture", "util"),
          "building blocks: checks, atomic writes, the cache, progress, threads, the one clock, kernels; this contract"),
    Layer("recordings", ("datasets",),
          "the sequence-folder contract, other ground-truth formats and the builders that write a folder"),
    Layer("results", ("report",),
          "results on disk: tables, figures, JSON, manifests and their provenance"),
    Layer("truth", ("groundtruth", "exclusion", "evaluate"),
          "the one definition of a loop, the one exclusion rule, scoring against them"),
    Layer("mapping", ("mapping",),
          "odometry and closures to a corrected trajectory: SE(3) poses, the pose graph (GTSAM), ATE / RPE"),
    Layer("descriptors", ("backbones", "similarity", "features"),
          "CNN ports and weights, similarity and whitening, whole-image descriptors"),
    Layer("methods", ("methods",),
          "one home per method (the paper's CNN + dictionary, SeqSLAM, greenloop-seq, the Siamese CNN, the "
          "single-frame matcher, RHLSH): its stages, its streaming detector, its registry entry; the registry"),
    Layer("speed", ("speed",),
          "measuring only: the one timing definition, the speed benchmark, the scaling benchmark"),
    Layer("study", ("study",),
          "around the pipeline: assembled tables, coverage, notebook parameters, sweeps, targets, "
          "leaderboard rows, provenance, verify"),
    Layer("experiments", ("experiments",),
          "one module per notebook's study, and default_choice"),
    Layer("run", ("detect", "short_recordings"),
          "a user's recording streamed through a registered detector: knobs, exclusion, windows, state; "
          "short recordings cut from a dataset and scored on that path"),
    Layer("entry", ("cli", "__main__"),
          "the command line: one module per command, argument parsing and printing only"),
)


class Import(NamedTuple):
    """One import of the package: ``module`` (dotted, the importer) imports ``target`` (dotted, a
    module of the package, or the package where the name is no module) at ``path``:``line``;
    ``local``: inside a function or class body."""
    module: str
    target: str
    path: Path
    line: int
    local: bool


def modules(root) -> dict[str, Path]:
    """{dotted module name: file} of every ``*.py`` under the package folder ``root`` (its folder
    name is the package name; ``pkg/__init__.py`` is ``pkg``)."""
    root = Path(root)
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = (root.name,) + path.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _local_lines(tree) -> set[int]:
    """Line numbers of the import statements inside a function or class body."""
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda)):
            lines |= {n.lineno for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom))}
    return lines


def imports(root) -> list[Import]:
    """Every import of the package ``root`` (a folder) by its own modules, in file and line order."""
    root = Path(root)
    package, found = root.name, modules(root)
    ours = lambda name: name == package or name.startswith(package + ".")
    out = []
    for module, path in found.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        local = _local_lines(tree)
        for node in ast.walk(tree):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names if ours(a.name)]
            elif isinstance(node, ast.ImportFrom):
                if node.level:                                  # relative: from its own package up
                    base = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                if ours(source):
                    targets = [f"{source}.{a.name}" if f"{source}.{a.name}" in found else source
                               for a in node.names]
            for target in targets:
                out.append(Import(module, target, path, node.lineno, node.lineno in local))
    return sorted(out, key=lambda i: (str(i.path), i.line, i.target))


def unit(name: str) -> str:
    """The unit of a dotted module name: ``greenloop.speed.bench`` -> ``speed``, ``greenloop`` ->
    ``__init__``."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def cycles(edges) -> list[list[str]]:
    """The import cycles of a graph {node: set of nodes}: its strongly connected components of more
    than one node (or a node with an edge to itself), each sorted, in sorted order."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    nodes = sorted(set(edges) | {t for ts in edges.values() for t in ts})

    def visit(v):                                             # Tarjan
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in edges.get(v, ()):
                out.append(sorted(comp))

    for v in nodes:
        if v not in index:
            visit(v)
    return sorted(out)


def check(root, layers=LAYERS) -> list[str]:
    """Every violation of the contract ``layers`` by the package folder ``root``, one sentence each
    (empty: it holds). See the module doc for the four rules."""
    root = Path(root)
    level = {}
    problems = []
    for i, layer in enumerate(layers):
        for u in layer.units:
            if u in level:
                problems.append(f"unit {u!r} is in two layers: {layers[level[u]].name!r} and {layer.name!r}")
            level.setdefault(u, i)
    present = {unit(m) for m in modules(root)}
    for u in sorted(present - set(level)):
        problems.append(f"{root.name}.{u} is in no layer of the contract: place it in one")
    for u in sorted(set(level) - present):
        problems.append(f"the contract names {u!r}, which is not in {root.name}/")
    edges: dict[str, set[str]] = {}
    module_edges: dict[str, set[str]] = {}
    for imp in imports(root):
        a, b = unit(imp.module), unit(imp.target)
        where = f"{imp.path.relative_to(root.parent)}:{imp.line}"
        if imp.local:
            problems.append(f"{where}: {imp.module} imports {imp.target} inside a function or class: "
                            f"import it at the top of the file")
        if imp.module != imp.target:
            module_edges.setdefault(imp.module, set()).add(imp.target)
        if a != b:
            edges.setdefault(a, set()).add(b)
            if a in level and b in level and level[b] > level[a]:
                problems.append(f"{where}: {imp.module} (layer {layers[level[a]].name!r}) imports "
                                f"{imp.target} (layer {layers[level[b]].name!r}, higher): an import up a layer")
    for cycle in cycles(edges):
        problems.append(f"import cycle among {', '.join(cycle)}")
    for cycle in cycles(module_edges):                 # inside one unit (across units: the line above)
        if len({unit(m) for m in cycle}) == 1:
            problems.append(f"import cycle among the modules {', '.join(cycle)}")
    return problems


def markdown(layers=LAYERS) -> str:
    """The layer listing docs/ARCHITECTURE.md holds: a Markdown table, the top layer first (imports
    run down it), one row per layer: its number (1: the bottom), name, units and what they are."""
    lines = ["| # | layer | units | what they are |", "| ---: | --- | --- | --- |"]
    for i, layer in reversed(list(enumerate(layers, 1))):
        units = ", ".join(f"`{u}`" for u in layer.units)
        lines.append(f"| {i} | {layer.name} | {units} | {layer.what} |")
    return "\n".join(lines) + "\n"
