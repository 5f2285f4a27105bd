"""results/PROVENANCE.md: where each notebook's results come from, read from what the runs wrote.

``python -m greenloop provenance [--out results/PROVENANCE.md] RESULTS...`` (``make provenance``)
writes one table per results folder (``results``, ``results/nordland``, ...), one row per folder of it
that holds a ``manifest.json`` (the notebooks, ``default_choice``): the git commit and whether the tree
was dirty, the environment hash, the CPU model and the date, from the manifest
(``greenloop.report.provenance``), and the duration, from the executed notebook beside it
(``<results>/<notebook>.ipynb``: papermill's ``metadata.papermill.duration``). Nothing is typed by hand
and nothing is guessed: a field an older manifest lacks shows ``—``.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

from greenloop.util.files import write_atomic

MISSING = "—"
COLUMNS = ["notebook", "commit", "environment", "CPU", "date", "duration"]


def _json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def papermill_duration(executed) -> float | None:
    """Seconds papermill took to run an executed notebook (its metadata.papermill.duration), or None."""
    nb = _json(Path(executed))
    d = ((nb or {}).get("metadata") or {}).get("papermill", {}).get("duration")
    return float(d) if isinstance(d, (int, float)) else None


def row(folder) -> dict:
    """One notebook folder's provenance as the table's cells (``—`` where the manifest says nothing)."""
    folder = Path(folder)
    m = _json(folder / "manifest.json") or {}
    if "git_commit" not in m:
        commit = MISSING
    elif m["git_commit"] is None:
        commit = "not a git checkout"
    else:
        commit = f"`{m['git_commit'][:12]}`" + {True: " (dirty)", False: ""}.get(m.get("git_dirty"), " (dirty?)")
    env = m.get("environment_hash")
    cpu = m.get("cpu_model") or m.get("cpu")             # manifests before cpu_model: the same reading, with cores
    duration = papermill_duration(folder.parent / f"{folder.name}.ipynb")
    if duration is not None:
        took = f"{duration:.1f} s"
    elif isinstance(m.get("wall_seconds"), (int, float)):
        took = f"{m['wall_seconds']:.1f} s †"
    else:
        took = MISSING
    return {"notebook": folder.name, "commit": commit, "environment": f"`{env[:12]}`" if env else MISSING,
            "CPU": cpu or MISSING, "date": m.get("date") or MISSING, "duration": took}


def rows(results_dir) -> list[dict]:
    """Every folder of a results folder that holds a manifest.json, in name order."""
    return [row(d) for d in sorted(Path(results_dir).iterdir()) if (d / "manifest.json").is_file()]


def dataset_name(folder) -> str | None:
    """The dataset a results folder's notebooks ran on (the first manifest's ``dataset``, last path part),
    or None where no manifest names one. The one reading of it: coverage, verdict, summary and verify use it."""
    for man in sorted(Path(folder).glob("[0-9][0-9]_*/manifest.json")):
        ds = (_json(man) or {}).get("dataset")
        if ds:
            return Path(str(ds).rstrip("/")).name
    return None


def markdown(results_dirs) -> str:
    """PROVENANCE.md's text: a header saying how each column is read, then a table per results folder."""
    parts = ["# Provenance of the results\n\n",
             "Written by `make provenance` (`python -m greenloop provenance`) from each folder's "
             "`manifest.json` and executed notebook; nothing is typed by hand. `—`: the manifest was "
             "written before that field was recorded.\n\n",
             "- **commit**: the checkout's `git rev-parse HEAD` when the notebook ran (first 12 digits); "
             "*(dirty)*: a tracked file that can change a result differed from it (any outside `results/`, `docs/`, "
             "`tests/` and `README.md`; manifests written until 7 December 2026 counted those too: Gardens Point's run "
             "of that day is marked dirty for edits to `docs/` and `README.md` made while it ran).\n",
             "- **environment**: sha256 of `python X.Y.Z\\n` (the interpreter's version) followed by "
             "the bytes of `environment.txt` (first 12 hex digits): equal values, same Python and pins.\n",
             "- **CPU**: `/proc/cpuinfo`'s model name (older manifests: the same, with the core count).\n",
             "- **date**: when the notebook wrote its manifest (UTC).\n",
             "- **duration**: papermill's run time of the executed notebook (`metadata.papermill.duration`); "
             "† where there is none, the process's age when it wrote its manifest (`wall_seconds`).\n"]
    for d in map(Path, results_dirs):
        table = rows(d)
        if not table:
            continue
        ds = dataset_name(d)
        parts.append(f"\n## `{d.as_posix()}`" + (f" ({ds})" if ds else "") + "\n\n")
        parts.append("| " + " | ".join(COLUMNS) + " |\n| " + " | ".join("---" for _ in COLUMNS) + " |\n")
        for r in table:
            parts.append("| " + " | ".join(str(r[c]).replace("|", "\\|") for c in COLUMNS) + " |\n")
    bench = bench_rows(Path(results_dirs[0]) / "bench") if results_dirs else []
    if bench:
        parts.append(f"\n## `{(Path(results_dirs[0]) / 'bench').as_posix()}` (the benchmarks)\n\n")
        parts.append("| " + " | ".join(COLUMNS) + " |\n| " + " | ".join("---" for _ in COLUMNS) + " |\n")
        for r in bench:
            parts.append("| " + " | ".join(str(r[c]) for c in COLUMNS) + " |\n")
    return "".join(parts)


BENCH = {"bench.json": "make bench", "scale.json": "make bench-scale", "stream100k.json": "make bench-stream"}
OLD_SCALE = "scale.md"   # a bench-scale run from before scale.json: its "Machine: ...; written <date>" line


def bench_rows(bench_dir) -> list[dict]:
    """The benchmarks' provenance (``results/bench``): bench.json's, scale.json's and stream100k.json's
    own date, CPU and (newer runs) commit and environment; without scale.json, scale.md's "Machine: ...; written <date>
    ..." line; ``—`` where the file says nothing. Duration: the JSON's ``wall_seconds``."""
    out = []
    for name, target in BENCH.items():
        path = Path(bench_dir) / name
        if not path.is_file() and name == "scale.json":
            name, path = OLD_SCALE, Path(bench_dir) / OLD_SCALE
        if not path.is_file():
            continue
        if name.endswith(".json"):
            m = _json(path) or {}
            commit = f"`{m['git_commit'][:12]}`" if m.get("git_commit") else MISSING
            took = f"{m['wall_seconds']:.1f} s †" if isinstance(m.get("wall_seconds"), (int, float)) else MISSING
            cpu, date, env = m.get("cpu_model") or m.get("cpu"), m.get("date"), m.get("environment_hash")
        else:
            line = next((t for t in path.read_text().splitlines() if t.startswith("Machine:")), "")
            cpu = line.removeprefix("Machine:").split(",")[0].strip() or None
            found = re.search(r"written (\S+ \S+ UTC)", line)
            date, commit, env, took = found.group(1) if found else None, MISSING, None, MISSING
        out.append({"notebook": f"{name} (`{target}`)", "commit": commit, "environment": f"`{env[:12]}`" if env else MISSING,
                    "CPU": cpu or MISSING, "date": date or MISSING, "duration": took})
    return out


def write_provenance(results_dirs, out) -> Path:
    """Write :func:`markdown` of these results folders to ``out``, atomically."""
    text = markdown(results_dirs)
    return write_atomic(Path(out), lambda p: p.write_text(text))
