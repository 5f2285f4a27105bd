"""Results on disk: atomic writes, paper-vs-run tables, figures, run manifests, results/tables.md.

Every notebook writes under ``<results_dir>/<notebook stem>/``; ``make`` assembles the ``*.md``
tables there into ``results/tables.md`` without re-executing anything
(``python -m greenloop.report results``).
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

PAPER, RUN = "paper", "this run"


def _atomic_write(path: Path, write) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".tmp-{path.name}-")
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


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
    return _atomic_write(path, lambda p: p.write_text(json.dumps(obj, indent=1, default=_default)))


def write_table(df, path, title: str | None = None, note: str | None = None) -> Path:
    """Write a pandas DataFrame as ``<path>.csv`` and ``<path>.md`` (a titled Markdown table).

    path: file path without suffix, e.g. results/01_spot_grouping/table1.
    Returns the .md path.
    """
    path = Path(path)
    _atomic_write(path.with_suffix(".csv"), lambda p: df.to_csv(p, index=False))
    md = (f"### {title}\n\n" if title else "") + df.to_markdown(index=False) + "\n"
    if note:
        md += f"\n{note}\n"
    return _atomic_write(path.with_suffix(".md"), lambda p: p.write_text(md))


def paper_vs_run(rows):
    """A table with the paper's value only as a reference column beside the measured one.

    rows: iterable of (quantity, paper value or None, measured value[, note]).
    Returns a DataFrame with columns: quantity | paper | this run | note.
    """
    import pandas as pd

    out = []
    for r in rows:
        q, paper, run, note = (list(r) + [""])[:4]
        out.append({"quantity": q, PAPER: "" if paper is None else paper, RUN: run, "note": note})
    return pd.DataFrame(out, columns=["quantity", PAPER, RUN, "note"])


def save_figure(fig, path, dpi: int = 110) -> Path:
    """Save a matplotlib figure as PNG atomically (and leave it open for inline display)."""
    path = Path(path).with_suffix(".png")
    return _atomic_write(path, lambda p: fig.savefig(p, dpi=dpi, bbox_inches="tight", format="png"))


def cpu_model() -> str:
    """The CPU's model name (from /proc/cpuinfo on Linux) and the number of cores visible."""
    name = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                name = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{name} ({os.cpu_count()} cores)"


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


def manifest(folder, parameters: dict, dataset: str | Path | None = None, **extra) -> Path:
    """Write ``<folder>/manifest.json``: date, machine, CPU, library versions, parameters,
    dataset path, fingerprint and ground-truth kind ('poses', 'pairs' or None), the wall time of
    this process so far (for a notebook executed by papermill: its kernel, i.e. the notebook's
    run time), plus any extra fields."""
    import time

    import psutil

    from . import data

    info = {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "wall_seconds": round(time.time() - psutil.Process().create_time(), 1),
            "machine": platform.node(), "platform": platform.platform(), "cpu": cpu_model(),
            "versions": versions(), "parameters": parameters}
    if dataset is not None:
        info["dataset"] = str(dataset)
        try:
            info["dataset_fingerprint"] = data.fingerprint(dataset)
        except (FileNotFoundError, ValueError) as e:
            info["dataset_fingerprint"] = f"unavailable: {e}"
        info["dataset_ground_truth"] = data.ground_truth_kind(dataset)
    info.update(extra)
    return write_json(Path(folder) / "manifest.json", info)


def assemble_tables(results_dir="results", out: str | Path | None = None) -> Path:
    """Concatenate every ``<results_dir>/<stem>/*.md`` into ``<results_dir>/tables.md``, one
    section per notebook in reading order, with each run's date and machine from its manifest."""
    results_dir = Path(results_dir)
    out = Path(out) if out else results_dir / "tables.md"
    parts = ["# greenloop: tables\n",
             "Assembled by `make` from the notebooks' own outputs; nothing here is typed by hand. "
             f"Paper values appear only in the `{PAPER}` column, beside the value measured in "
             f"`{RUN}`.\n"]
    folders = sorted(p for p in results_dir.iterdir() if p.is_dir() and p.name[:2].isdigit())
    folders += [results_dir / "bench"] if (results_dir / "bench").is_dir() else []
    for folder in folders:
        tables = sorted(folder.glob("*.md"))
        if not tables:
            continue
        parts.append(f"\n## {folder.name}\n")
        man = folder / "manifest.json"
        if man.is_file():
            m = json.loads(man.read_text())
            parts.append(f"_Run {m.get('date', '?')} on {m.get('cpu', '?')}; dataset "
                         f"`{m.get('dataset', '?')}` ({m.get('dataset_fingerprint', '?')})._\n")
        for t in tables:
            parts.append("\n" + t.read_text())
    return _atomic_write(out, lambda p: p.write_text("".join(parts)))


if __name__ == "__main__":
    print(assemble_tables(*(sys.argv[1:2] or ["results"])))
