"""Results on disk: atomic writes, paper-vs-run tables, figures, run manifests, results/tables.md.

Every notebook writes under ``<results_dir>/<notebook stem>/``; ``make`` assembles the ``*.md``
tables there into ``results/tables.md`` without re-executing anything
(``python -m greenloop.study.report results``), and the results of several datasets into one table
(``python -m greenloop.study.report --datasets results/datasets.md results results/nordland``).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import psutil

from greenloop.datasets import sequence
from greenloop.study import coverage
from greenloop.util.files import write_atomic  # the one atomic file write, also report.write_atomic

PAPER, RUN = "paper", "this run"
ROOT = Path(__file__).resolve().parents[2]   # the checkout greenloop runs from


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


def git_state(root=None) -> dict:
    """{'git_commit': HEAD's sha of the checkout greenloop runs from (root, default ROOT), 'git_dirty':
    whether a tracked file outside results/ differs from it} (``git status --porcelain
    --untracked-files=no -- . ':(exclude)results'``: a run rewrites results/ itself). Both None
    where root is not the top of a git checkout, or without git."""
    root = Path(root or ROOT)

    def git(*args):
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=60)
    try:
        top = git("rev-parse", "--show-toplevel")
        if top.returncode != 0 or Path(top.stdout.strip()).resolve() != root.resolve():
            return {"git_commit": None, "git_dirty": None}
        head = git("rev-parse", "HEAD")
        status = git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)results")
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


def manifest(folder, parameters: dict, dataset: str | Path | None = None, **extra) -> Path:
    """Write ``<folder>/manifest.json``: :func:`provenance` (date, git commit and whether the tree
    was dirty, environment hash, CPU model, platform), the wall time of this process so far (for a
    notebook executed by papermill: its kernel, i.e. the notebook's run time until this call),
    library versions, parameters, dataset path, fingerprint and ground-truth kind ('poses', 'pairs'
    or None), plus any extra fields."""
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
    if (results_dir / "coverage.md").is_file():
        parts.append("\n## Coverage of the papers\n\n" + (results_dir / "coverage.md").read_text())
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
    return write_atomic(out, lambda p: p.write_text("".join(parts)))


def _json(path: Path):
    return json.loads(path.read_text()) if path.is_file() else None


def _dataset_rows(folder: Path) -> list[dict]:
    """One results folder's headline numbers as long rows (method, metric, value)."""
    rows = []
    s07 = _json(folder / "07_feature_baselines" / "summary.json")
    for r in (s07 or {}).get("table", []):
        for metric in ("AP_%", "R@100P_%", "R@1_%"):
            if metric in r:
                rows.append({"method": f"{r['label']}, cosine", "metric": metric, "value": r[metric]})
    s13 = _json(folder / "13_leaderboard" / "summary.json")
    for r in (s13 or {}).get("leaderboard", []):
        r1 = r.get("R@1_%")                               # None or NaN: not run (e.g. no honest split)
        if (r["method"] in ("greenloop-seq", "greenloop-seq-fast", "SeqSLAM (published)") and r1 is not None
                and r1 == r1 and r.get("mode", "loop closure") == "loop closure"):
            name = f"{r['method']}, evaluation part of the leaderboard split (loop closure)"
            for metric in ("R@1_%", "AUC-PR_%", "R@100P_%"):   # per query; greenloop-seq's descriptor is picked per dataset
                rows.append({"method": name, "metric": metric,
                             "value": f"{r[metric]} ({str(r.get('knobs', '')).split(',')[0]})"})
            if r.get("queries") is not None:               # what they rest on (summaries before the counts: absent)
                rows.append({"method": name, "metric": "queries (revisit queries)",
                             "value": f"{int(r['queries'])} ({int(r['revisit_queries'])})"})
    s01 = _json(folder / "01_spot_grouping" / "summary.json")
    for r in (s01 or {}).get("table1", []):
        rows.append({"method": f"paper's CNN, L = {r['frames_per_spot']}, random 80/20 split (Table 1)",
                     "metric": "accuracy_%", "value": f"{r['acc_mean_%']:.1f} ± {r['acc_std_%']:.1f} ({r['seeds']} seeds)"})
    s12 = _json(folder / "12_revisit_protocol" / "summary.json")
    if s12:
        ps = pd.DataFrame(s12["per_seed"])
        for split, g in ps.groupby("split"):
            for col, what in (("in_traversal_test_acc_%", "first traversal, test split"),
                              ("revisit_acc_%", "revisit frames")):
                rows.append({"method": f"paper's CNN trained on the first traversal ({split} split), "
                                       f"scored on the {what}", "metric": "accuracy_%",
                             "value": f"{g[col].mean():.1f} ± {g[col].std():.1f} ({len(g)} seeds)"})
        d = pd.DataFrame(s12["dictionary"])
        for rule, g in d.groupby("tau_rule"):
            rows.append({"method": f"paper's CNN + dictionary, τ {rule}", "metric": "precision / recall",
                         "value": f"{g.precision.mean():.3f} / {g.recall.mean():.3f} (τ {sorted(set(g.tau))})"})
    return rows


def cross_dataset(results_dirs) -> pd.DataFrame:
    """One table across datasets: each method's headline numbers side by side.

    results_dirs: results folders (``results``, ``results/nordland``, ...), each holding the
    outputs of ``make all`` on one dataset; the dataset name is read from its manifests.
    Returns a DataFrame: one row per (method, metric), one column per dataset (missing: blank).
    """
    frames = []
    for folder in map(Path, results_dirs):
        man = next((m for m in sorted(folder.glob("[0-9][0-9]_*/manifest.json"))), None)
        if man is None:
            continue
        name = Path(json.loads(man.read_text()).get("dataset", folder.name)).name
        rows = _dataset_rows(folder)
        if rows:
            frames.append(pd.DataFrame(rows).assign(dataset=name))
    if not frames:
        raise FileNotFoundError(f"none of {list(map(str, results_dirs))} holds notebook results: "
                                f"run `make all` (and `make all DATASET=... RESULTS=...`) first")
    long = pd.concat(frames)
    wide = long.pivot_table(index=["method", "metric"], columns="dataset", values="value",
                            aggfunc="first", sort=False)
    return wide.reset_index().fillna("")


def write_cross_dataset(results_dirs, out) -> Path:
    """Write :func:`cross_dataset` as ``out`` (.md and .csv)."""
    table = cross_dataset(results_dirs)
    return write_table(table, Path(out).with_suffix(""), title="One table across datasets",
                       note="Assembled from each dataset's notebook outputs (07: descriptors with "
                            "cosine similarity, scored against that dataset's ground truth; 13: "
                            "greenloop's sequence detector and SeqSLAM on the leaderboard's evaluation part, per-query metrics, loop-closure mode; 01: the "
                            "main paper's Table 1 protocol; 12: the CNN trained on the first traversal "
                            "and scored on the revisit). Every weight label is in the method name.")


def write_coverage(results_dirs, out) -> Path:
    """Write :func:`greenloop.study.coverage.coverage` of these results folders as ``out`` (.md, .csv)."""
    return write_table(coverage.coverage(results_dirs), Path(out).with_suffix(""),
                       title="Coverage: every table and figure of the five papers",
                       note="Status read from the results folders (greenloop.study.coverage): an item whose "
                            "output is in none of them is 'not run'. `datasets`: where its output is.")


def main(argv=None) -> int:
    """CLI (``make`` calls it): assemble RESULTS/tables.md, or with --datasets / --coverage write
    one table across results folders. Prints the file written."""
    ap = argparse.ArgumentParser(prog="python -m greenloop.study.report",
                                 description="Assemble the notebooks' tables from a results folder.")
    ap.add_argument("results", nargs="*", default=["results"],
                    help="results folder (default results); with --datasets/--coverage: every folder to read")
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--datasets", metavar="OUT", help="write one table across the results folders (.md, .csv)")
    group.add_argument("--coverage", metavar="OUT", help="write the papers' coverage read from the results folders")
    args = ap.parse_args(argv)
    missing = [d for d in args.results if not Path(d).is_dir()]
    if missing:
        ap.error(f"no such results folder: {', '.join(missing)} (run `make all` first, or name another)")
    if args.datasets:
        print(write_cross_dataset(args.results, args.datasets))
    elif args.coverage:
        print(write_coverage(args.results, args.coverage))
    elif len(args.results) != 1:
        ap.error("give one results folder (or --datasets / --coverage for several)")
    else:
        print(assemble_tables(args.results[0]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
