"""Results on disk: atomic writes, JSON, tables (paper value beside this run's), figures, run
manifests and the provenance they record (date, git commit, environment hash, CPU).

Every notebook, ``make bench``, ``make bench-scale`` and ``make default-choice`` write their outputs
through these functions, under ``<results_dir>/<notebook stem>/`` for a notebook.
``greenloop.study.report`` assembles what they wrote into ``results/tables.md`` and the tables
across datasets. A low layer (docs/ARCHITECTURE.md, ``greenloop.architecture``): it imports
``util.files`` and ``datasets.sequence`` (a manifest names its dataset's fingerprint) only, so
that every layer above may write results.
"""
from __future__ import annotations

import ast
import datetime as _dt
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import psutil

from greenloop.datasets import sequence
from greenloop.util.files import write_atomic  # the one atomic file write, also report.write_atomic

PAPER, RUN = "paper", "this run"
ROOT = Path(__file__).resolve().parents[1]   # the checkout greenloop runs from


def _default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"cannot write {type(o)} to JSON")


def write_json(path, obj) -> Path:
    """Write ``obj`` (numpy scalars/arrays allowed) as indented JSON, atomically."""
    return write_atomic(path, lambda p: p.write_text(json.dumps(obj, indent=1, default=_default)))


def rounded(df, decimals=None, columns=None):
    """df with its float columns rounded where a table is written (experiments return unrounded
    frames): every numeric column to ``decimals`` places (None: left as is), the columns named in
    ``columns`` ({column: places}) to theirs instead. Returns a new DataFrame."""
    columns = dict(columns or {})
    unknown = [c for c in columns if c not in df.columns]
    if unknown:
        raise ValueError(f"columns {unknown} to round are not in the table {list(df.columns)}: name its columns")
    places = {c: columns.get(c, decimals) for c in df.columns}
    return df.round({c: n for c, n in places.items() if n is not None})


def records(df, decimals=None, columns=None) -> list[dict]:
    """df as JSON records (one dict per row), rounded as :func:`rounded` rounds a written table."""
    return rounded(df, decimals, columns).to_dict("records")


def write_table(df, path, title: str | None = None, note: str | None = None, decimals=None,
                columns=None) -> Path:
    """Write a pandas DataFrame as ``<path>.csv`` and ``<path>.md`` (a titled Markdown table).

    path: file path without suffix, e.g. results/01_spot_grouping/table1.
    decimals, columns: round the written numbers (:func:`rounded`); None writes them as they are.
    Returns the .md path.
    """
    path = Path(path)
    df = rounded(df, decimals, columns)
    write_atomic(path.with_suffix(".csv"), lambda p: df.to_csv(p, index=False))
    md = (f"### {title}\n\n" if title else "") + df.to_markdown(index=False) + "\n"
    if note:
        md += f"\n{note}\n"
    return write_atomic(path.with_suffix(".md"), lambda p: p.write_text(md))


def paper_vs_run(rows):
    """A table with the paper's value only as a reference column beside the measured one.

    rows: iterable of (quantity, paper value or None, measured value[, note[, decimals]]): a
    numeric measured value is shown rounded to ``decimals`` (``round``) where that is given.
    Returns a DataFrame with columns: quantity | paper | this run | note.
    """
    out = []
    for r in rows:
        q, paper, run, note, decimals = (list(r) + ["", None][len(r) - 3:])[:5]
        if decimals is not None and isinstance(run, (int, float, np.number)) and not isinstance(run, bool):
            run = round(run, decimals)
        out.append({"quantity": q, PAPER: "" if paper is None else paper, RUN: run, "note": note})
    return pd.DataFrame(out, columns=["quantity", PAPER, RUN, "note"])


def fill_block(markdown_file, name: str, content: str) -> Path:
    """Replace what lies between ``<!-- {name}:start -->`` and ``<!-- {name}:end -->`` in a Markdown
    file (the README's generated tables) with ``content``. Raises ValueError without the markers."""
    path = Path(markdown_file)
    text = path.read_text()
    start, end = f"<!-- {name}:start -->\n", f"<!-- {name}:end -->"
    if start not in text or end not in text:
        raise ValueError(f"{path} has no {start.strip()} ... {end} block to fill")
    head, rest = text.split(start, 1)
    write_atomic(path, head + start + content + end + rest.split(end, 1)[1])
    return path


def palette(names) -> dict:
    """{name: colour}: one distinct colour per name, in the order given (tab20, then tab20b and
    tab20c: up to 60 names), so that a method keeps its colour across a notebook's panels."""
    colours = [plt.get_cmap(m)(i) for m in ("tab20", "tab20b", "tab20c") for i in range(20)]
    return {n: colours[k % len(colours)] for k, n in enumerate(dict.fromkeys(names))}


def mark_paper(ax, x, y, label: str, horizontal: bool = True, width: float = 0.8):
    """The paper's value(s) on ``ax``: a dashed black segment of ``width`` centred on each (x, y)
    (horizontal bars: along x; ``horizontal`` False: a dashed vertical segment at x = y for barh),
    one legend entry ``label``. x, y: sequences of equal length (bar positions, values)."""
    first = True
    for xi, yi in zip(x, y):
        if yi is None or yi != yi:
            continue
        seg = ([xi - width / 2, xi + width / 2], [yi, yi]) if horizontal else ([yi, yi], [xi - width / 2, xi + width / 2])
        ax.plot(*seg, color="k", ls="--", lw=1.6, label=label if first else None, zorder=4)
        first = False


def label_figure(fig, label: str):
    """Write ``label`` (e.g. "budget-limited: ...") in red above the figure, over its title and
    outside the axes (the saved figure's tight bounding box takes it in); nothing for "". Returns
    the figure."""
    if label:
        fig.text(0.5, 1.0, label, ha="center", va="bottom", color="tab:red", fontsize=11)
    return fig


def save_figure(fig, path, dpi: int = 110) -> Path:
    """Save a matplotlib figure as PNG atomically (and leave it open for inline display)."""
    path = Path(path).with_suffix(".png")
    return write_atomic(path, lambda p: fig.savefig(p, dpi=dpi, bbox_inches="tight", format="png"))


def cpu_name() -> str:
    """The CPU's model name: /proc/cpuinfo's first 'model name' on Linux, else what the platform
    module says (the processor, else the architecture)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def cpu_model() -> str:
    """The CPU's model name (:func:`cpu_name`) and the number of cores visible."""
    return f"{cpu_name()} ({os.cpu_count()} cores)"


# tracked paths whose edits cannot change a result: git_state's dirty flag leaves them out
NOT_RESULT_INPUTS = ("results", "docs", "tests", "README.md")


def git_state(root=None) -> dict:
    """{'git_commit': HEAD's sha of the checkout greenloop runs from (root, default ROOT), 'git_dirty':
    whether a tracked file that can change a result differs from it} (``git status --porcelain
    --untracked-files=no`` outside NOT_RESULT_INPUTS: results/, which a run rewrites itself, and the
    prose and tests, which no notebook reads). Both None where root is not the top of a git
    checkout, or without git."""
    root = Path(root or ROOT)

    def git(*args):
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=60)
    try:
        top = git("rev-parse", "--show-toplevel")
        if top.returncode != 0 or Path(top.stdout.strip()).resolve() != root.resolve():
            return {"git_commit": None, "git_dirty": None}
        head = git("rev-parse", "HEAD")
        status = git("status", "--porcelain", "--untracked-files=no", "--", ".",
                     *(f":(exclude){p}" for p in NOT_RESULT_INPUTS))
    except (OSError, subprocess.SubprocessError):
        return {"git_commit": None, "git_dirty": None}
    return {"git_commit": head.stdout.strip() if head.returncode == 0 else None,
            "git_dirty": bool(status.stdout.strip()) if status.returncode == 0 else None}


def environment_hash(path=None) -> str | None:
    """sha256 (hex) of the bytes ``python <X.Y.Z>\\n`` (this interpreter's platform.python_version())
    followed by the bytes of environment.txt, the pinned packages: equal hashes, same Python and same
    pins. path: default ROOT/environment.txt. None where it is absent."""
    try:
        pins = Path(path or ROOT / "environment.txt").read_bytes()
    except OSError:
        return None
    return hashlib.sha256(f"python {platform.python_version()}\n".encode() + pins).hexdigest()


def provenance() -> dict:
    """Where and from what a result comes: date (UTC), git commit and dirty flag (:func:`git_state`),
    environment hash (:func:`environment_hash`), CPU model (:func:`cpu_name`), the CPU with its core
    count (:func:`cpu_model`) and the platform."""
    return {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"), **git_state(),
            "environment_hash": environment_hash(), "cpu_model": cpu_name(), "cpu": cpu_model(),
            "platform": platform.platform()}


def versions() -> dict:
    """Versions of the libraries the results depend on."""
    import importlib.metadata as md

    out = {"python": sys.version.split()[0]}
    for pkg in ("numpy", "tensorflow", "keras", "jax", "scikit-learn", "opencv-python-headless",
                "pandas", "matplotlib", "papermill"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            pass
    try:
        import keras
        out["keras_backend"] = keras.backend.backend()
    except Exception:  # keras absent is fine for a manifest
        pass
    return out


# The first line of the cell papermill injects after a notebook's cell tagged ``parameters`` (its
# PythonTranslator.codify: the comment "Parameters", then one assignment per passed parameter).
INJECTED = "# Parameters"


def _assigned(source: str) -> tuple[list[str], bool]:
    """(the names a cell's top-level assignments bind, in order: ``x = ...``, ``x: T = ...``,
    ``x = y = ...``; whether the cell holds nothing else but comments and a docstring)."""
    names, only = [], True
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and all(isinstance(t, ast.Name) for t in node.targets):
            names += [t.id for t in node.targets]
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value is not None:
            names.append(node.target.id)
        elif not (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)):
            only = False
    return list(dict.fromkeys(names)), only


def parameters(namespace: dict, **derived) -> dict:
    """The notebook's parameters as this run set them, then ``derived``: {name: value} for every
    name its cell tagged ``parameters`` assigns, valued as ``namespace`` holds it (pass ``globals()``:
    the value papermill injected wins over the cell's default), then each ``derived`` value (one the
    notebook computed, e.g. the frame step it used or its exclusion in steps). A derived value named
    as a parameter replaces it: the manifest then records what the run used under that name; state
    the given one under another name where it differs (notebook 13: ``frame_step_requested``).

    The names come from the kernel's own input history (``In`` in ``namespace``), not from a
    notebook file: papermill executes its injected cell (first line :data:`INJECTED`) right after the
    cell tagged ``parameters``, so the cell the kernel ran just before the last injected one is the
    parameters cell, whatever the notebook's path, name or folder and the working directory
    (``make``'s notebooks/ run from the checkout, the tests' and ``make sweep``'s runs into temporary
    folders, a user's copy elsewhere). Where nothing was injected (papermill without parameters, or a
    notebook run top to bottom by hand) the values are the cell's own and the cell is the first the
    kernel ran: a notebook's parameters cell is its first code cell (tests/test_report.py checks the
    study's notebooks). Only assignments count: a name papermill injected that the cell does not
    declare is left out (papermill warns "Passed unknown parameter").

    Values are returned as given (lists, strings, None: JSON as :func:`manifest` writes them; numpy
    scalars and Paths are converted by :func:`write_json`). Raises ValueError without an input
    history, without a parameters cell, or where a parameter is not in ``namespace``."""
    history = namespace.get("In")
    if not isinstance(history, list) or len(history) < 2:
        raise ValueError("report.parameters reads the kernel's input history (In): call it from a notebook's "
                         "cell as report.parameters(globals())")
    injected = [k for k, src in enumerate(history) if src.split("\n", 1)[0].strip() == INJECTED]
    if injected:
        k = injected[-1] - 1
        if k < 1:
            raise ValueError("papermill injected the parameters before any cell ran: the notebook has no cell "
                             "tagged 'parameters' (tag its parameters cell so)")
        names = _assigned(history[k])[0]
    else:
        names, only = _assigned(history[1])
        if not only:
            raise ValueError("the first cell this kernel ran is not a parameters cell (assignments only): run the "
                             "notebook from the top, or with papermill")
    missing = [n for n in names if n not in namespace]
    if missing:
        raise ValueError(f"parameters {missing} of the parameters cell are not in the namespace given: pass globals()")
    return {**{n: namespace[n] for n in names}, **derived}


def manifest(folder, parameters: dict, dataset: str | Path | None = None, **extra) -> Path:
    """Write ``<folder>/manifest.json``: :func:`provenance` (date, git commit and whether the tree
    was dirty, environment hash, CPU model, platform), the wall time of this process so far (for a
    notebook executed by papermill: its kernel, i.e. the notebook's run time until this call),
    library versions, parameters (a notebook's: :func:`parameters`, never a dict typed again), dataset
    path, fingerprint and ground-truth kind ('poses', 'pairs' or None), plus any extra fields."""
    info = {**provenance(), "wall_seconds": round(time.time() - psutil.Process().create_time(), 1),
            "versions": versions(), "parameters": parameters}
    if dataset is not None:
        info["dataset"] = str(dataset)
        try:
            info["dataset_fingerprint"] = sequence.fingerprint(dataset)
        except (FileNotFoundError, ValueError) as e:
            info["dataset_fingerprint"] = f"unavailable: {e}"
        info["dataset_ground_truth"] = sequence.ground_truth_kind(dataset)
    info.update(extra)
    return write_json(Path(folder) / "manifest.json", info)
