"""results/tables.md and the tables across results folders, assembled from what the notebooks wrote.

Every notebook writes under ``<results_dir>/<notebook stem>/`` (through ``greenloop.report``);
``make`` assembles the ``*.md`` tables there into ``results/tables.md`` without re-executing anything
(``python -m greenloop tables results``), and the results of several datasets into one table
(``python -m greenloop tables --datasets results/datasets.md results results/nordland``).
"""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from greenloop.report import PAPER, RUN, write_table
from greenloop.study import coverage, verdict
from greenloop.util.files import write_atomic


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
    return write_table(coverage_with_claims(results_dirs), Path(out).with_suffix(""),
                       title="Coverage: every table and figure of the five papers",
                       note="Status read from the results folders (greenloop.study.coverage): whether the "
                            "protocol ran ('not run': its output is in none of them); `datasets`: where its output "
                            "is; `claim holds`: the verdicts of the paper's claims on it, per dataset "
                            "(greenloop.study.verdict, results/verdict.md).")


def coverage_with_claims(results_dirs) -> pd.DataFrame:
    """:func:`greenloop.study.coverage.coverage` with a ``claim holds`` column after ``status``:
    :func:`greenloop.study.verdict.claim_holds` of each row."""
    t = coverage.coverage(results_dirs)
    t.insert(t.columns.get_loc("status") + 1, "claim holds",
             [verdict.claim_holds(p, i, results_dirs) for p, i in zip(t.paper, t["item"])])
    return t
