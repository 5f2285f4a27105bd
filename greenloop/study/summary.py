"""results/summary.md: every leaderboard row, the main paper's detector as a loop-closure detector, the
detector's targets and the long-recording benchmark on one page, read from the committed tables.

``python -m greenloop summary [--out results/summary.md] [--bench results/bench] RESULTS...``
(``make summary``) reads, for each results folder (``results``, ``results/nordland``, ...; its dataset
named as PROVENANCE.md names it, from its notebooks' manifests):

- ``13_leaderboard/leaderboard.csv``: every row, one table per mode, with closure precision
  ((declared - false) / declared) and closure recall ((declared - false) / revisit queries) in %;
- ``13_leaderboard/comparisons.csv``: the paired differences whose ``a`` is greenloop's named
  configurations (:data:`NAMED`);
- ``13_leaderboard/targets.csv``: every row;
- ``01_spot_grouping/table1.csv`` (the CNN's accuracy at L = 60) and ``06_speed/paper_vs_run.csv``
  (frames per second), beside the leaderboard's main-paper row;

and, for the long recordings, ``bench/scale_decisions.csv`` with a link to ``bench/scale.md``. The
header gives each folder's commit, CPU and date from the manifests of the notebooks read
(``greenloop.study.provenance.row``). Cells are the tables' own numbers, written as their markdown
writes them (``g``: up to 6 significant digits, integral values without a decimal point; scale.md's
``.4g`` for scale_decisions.csv), ``–`` where a cell is empty or a column absent. The only
arithmetic is closure precision and recall (2 decimals, as the leaderboard's own percentages) and
the pair rates as % (their digits kept). A table that is missing gives a line naming it, never an
exception.
"""
from __future__ import annotations

import csv
import os
import re
from pathlib import Path

from greenloop.report import fill_block
from greenloop.study import convergence, provenance, targets as goals
from greenloop.util.files import write_atomic

DASH = "–"
NAMED = ("greenloop-seq-grad", "greenloop-seq-cnn")      # greenloop's named configurations
MAIN_PAPER = "main paper"                                  # the leaderboard's main-paper row starts so
SPOT_FRAMES = 60.0                                         # L, frames per spot, of the accuracy shown
LB, T1, SPEED = "13_leaderboard", "01_spot_grouping", "06_speed"
PAIR = re.compile(r"pair precision ([-+0-9.eE]+), recall ([-+0-9.eE]+)")
LEADERBOARD = ["method", "queries", "revisit queries", "R@1 % [lo, hi]", "AUC-PR %", "R@100P %",
               "frames/s median [min, max]", "bytes per stored frame", "closures declared",
               "closures false", "closure precision %", "closure recall %"]
TARGETS = ["protocol", "configuration", "target", "measured", "required", "met", "queries",
           "revisit_queries"]


def read_csv(path) -> list[dict] | None:
    """The rows of a CSV file as {column: text, as written}, or None where the file is missing."""
    try:
        with open(path, newline="") as f:
            return list(csv.DictReader(f))
    except FileNotFoundError:
        return None


def missing(path) -> str:
    """The line a missing table gives."""
    return f"`{Path(path).as_posix()}` is missing: nothing to show from it.\n"


def _float(cell) -> float | None:
    """A cell as a number, or None (empty, absent, not a number, NaN)."""
    try:
        x = float(cell)
    except (TypeError, ValueError):
        return None
    return None if x != x else x


def num(cell, fmt: str = "g") -> str:
    """A cell as the tables' markdown writes it: a number with ``fmt`` (an integral value without a
    decimal point), other text as written, ``–`` where empty or absent."""
    if cell is None or str(cell).strip() == "" or str(cell).lower() == "nan":
        return DASH
    x = _float(cell)
    if x is None:
        return str(cell)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else format(x, fmt)


def interval(value, lo, hi) -> str:
    """``value [lo, hi]`` (the bounds left out where the table has none), ``–`` without a value."""
    if num(value) == DASH:
        return DASH
    return num(value) if num(lo) == DASH or num(hi) == DASH else f"{num(value)} [{num(lo)}, {num(hi)}]"


def table(header, rows) -> str:
    """A markdown table of these cells (``|`` inside a cell escaped)."""
    line = lambda cells: "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |\n"
    return line(header) + line(["---"] * len(header)) + "".join(line(r) for r in rows)


def closure_rates(row: dict) -> tuple[float | None, float | None]:
    """A leaderboard row's closure precision and recall, in %: (declared - false) / declared and
    (declared - false) / revisit_queries (the share of revisit queries given a correct closure);
    each None where a count it needs is empty, absent or zero."""
    declared, false = _float(row.get("closures_declared")), _float(row.get("closures_false"))
    revisit = _float(row.get("revisit_queries"))
    if declared is None or false is None:
        return None, None
    correct = declared - false
    return (100 * correct / declared if declared else None), (100 * correct / revisit if revisit else None)


def percent(x: float | None) -> str:
    """A computed percentage as the leaderboard writes its own: 2 decimals, ``–`` for None."""
    return DASH if x is None else num(round(x, 2))


def pair_rates(note) -> tuple[float | None, float | None]:
    """Pair precision and recall, in %, from a scored_on note's "pair precision X, recall Y"
    (fractions there; the % keeps their digits: 0.217 -> 21.7), or (None, None)."""
    m = PAIR.search(note or "")
    if not m:
        return None, None
    as_percent = lambda t: round(100 * float(t), max(len(t.partition(".")[2]) - 2, 0))
    return as_percent(m.group(1)), as_percent(m.group(2))


def name(folder) -> str:
    """A results folder as the page names it: its path and, where a manifest says, its dataset."""
    ds = provenance.dataset_name(folder)              # the dataset name PROVENANCE.md gives the folder
    return f"`{Path(folder).as_posix()}`" + (f" ({ds})" if ds else "")


def header(results_dirs) -> str:
    """The page's opening: how it is written and from what, then each folder's commit, CPU and date
    of the notebooks whose tables it reads."""
    rows = []
    for d in map(Path, results_dirs):
        for nb in (LB, T1, SPEED):
            r = {k: DASH if v == provenance.MISSING else v for k, v in provenance.row(d / nb).items()}
            rows.append([name(d), nb, r["commit"], r["CPU"], r["date"]])
    return ("# Summary: leaderboards, the main paper's detector, the detector's targets\n\n"
            "Written by `make summary` (`python -m greenloop summary`) from the tables each section "
            "names (each folder's `13_leaderboard/leaderboard.csv`, `comparisons.csv`, `targets.csv`, "
            "`01_spot_grouping/table1.csv`, `06_speed/paper_vs_run.csv`; `bench/scale_decisions.csv`); "
            "nothing is typed by hand. Numbers as the tables' markdown writes them (closure precision and "
            "recall: 2 decimals); `–`: an empty cell or a column the table does not have. Where each notebook "
            "ran (its `manifest.json`, as in PROVENANCE.md):\n\n" + table(["folder", "notebook", "commit", "CPU", "date"], rows))


def leaderboard_cells(row: dict) -> list[str]:
    """One leaderboard row as :data:`LEADERBOARD`'s cells (R@1, AUC-PR, R@100P, precision, recall
    in %; frames/s; bytes)."""
    precision, recall = closure_rates(row)
    g = row.get
    return [g("method") or DASH, num(g("queries")), num(g("revisit_queries")),
            interval(g("R@1_%"), g("R@1_lo_%"), g("R@1_hi_%")), num(g("AUC-PR_%")), num(g("R@100P_%")),
            interval(g("fps_median"), g("fps_min"), g("fps_max")), num(g("bytes_per_stored_frame")),
            num(g("closures_declared")), num(g("closures_false")), percent(precision), percent(recall)]


def scored_on(rows) -> str:
    """The rows' ``scored_on`` note, once; where they differ, each distinct note with the rows it
    covers (the most common one counted, the others named)."""
    notes: dict[str, list[str]] = {}
    for r in rows:
        notes.setdefault(r.get("scored_on") or DASH, []).append(r.get("method") or DASH)
    if len(notes) == 1:
        return f"Scored on: {next(iter(notes))}.\n"
    common = max(notes, key=lambda n: len(notes[n]))
    return "Scored on (the rows' notes differ):\n\n" + "".join(
        f"- {n} ({len(ms)} rows)\n" if n == common else f"- {n} ({'; '.join(ms)})\n" for n, ms in notes.items())


def leaderboard_section(folder: Path) -> str:
    """A folder's leaderboard: one table per mode (in the file's order), every row, then the mode's
    scored_on note."""
    path = folder / LB / "leaderboard.csv"
    rows = read_csv(path)
    if rows is None:
        return missing(path)
    parts = [f"From `{path.as_posix()}`.\n"]
    if rows and "revisit_queries" not in rows[0]:
        parts.append("\nThis leaderboard.csv has no `queries` / `revisit_queries` columns (written before "
                     "notebook 13 recorded them): closure recall, which needs them, shows –.\n")
    for mode in dict.fromkeys(r.get("mode") or DASH for r in rows):
        mine = [r for r in rows if (r.get("mode") or DASH) == mode]
        parts += [f"\n#### {mode}\n\n", table(LEADERBOARD, [leaderboard_cells(r) for r in mine]), "\n",
                  scored_on(mine)]
    return "".join(parts)


def comparisons_section(folder: Path) -> str:
    """The paired comparisons (a minus b, percentage points, on the same queries) whose ``a`` is one
    of :data:`NAMED`, or one line where the folder wrote none."""
    path = folder / LB / "comparisons.csv"
    rows = read_csv(path)
    if rows is None:
        return f"No paired comparisons: this folder has no `{path.as_posix()}`.\n"
    ours = [[r.get("protocol") or DASH, r.get("a"), r.get("b") or DASH, r.get("metric") or DASH,
             interval(r.get("difference"), r.get("lo"), r.get("hi")), pair_word(r),
             num(r.get("queries"))] for r in rows if r.get("a") in NAMED]
    head = (f"Paired comparisons from `{path.as_posix()}` (a minus b on the same queries, percentage points, "
            f"95 % interval), rows whose a is {' or '.join(NAMED)}. {goals.PAIRED_RULE}\n\n")
    if not ours:
        return head + "none.\n"
    return head + table(["protocol", "a", "b", "metric", "difference [lo, hi]", "paired", "queries"], ours)


DEFAULT, CNN, SEQSLAM = "greenloop-seq-grad", "greenloop-seq-cnn", "SeqSLAM (tuned)"
LEADERBOARD_PROTOCOL = "leaderboard"        # comparisons.csv's protocol of the leaderboard's own rows
STANDING = ["dataset", "protocol", "mode", "queries", f"{DEFAULT} (the default) R@1 %", f"{CNN} R@1 %",
            f"{SEQSLAM} R@1 %", "best single frame R@1 %", f"default minus {SEQSLAM}, paired",
            "default frames/s [slowest, fastest]"]


def pair_word(row: dict) -> str:
    """A comparisons.csv row's paired interval in words (``study.targets.paired_word``), "–" without one."""
    lo, hi = _float(row.get("lo")), _float(row.get("hi"))
    return DASH if lo is None or hi is None else goals.paired_word(lo, hi)


def _r1(row: dict | None) -> str:
    return DASH if row is None else interval(row.get("R@1_%"), row.get("R@1_lo_%"), row.get("R@1_hi_%"))


def _paired(folder: Path, mode: str, protocol: str = LEADERBOARD_PROTOCOL) -> str:
    """The default minus SeqSLAM tuned in R@1, points [95 % paired interval] and its word
    (:func:`pair_word`), from comparisons.csv (loop closure, the rows of ``protocol``; "–" where the
    folder wrote none)."""
    rows = read_csv(folder / LB / "comparisons.csv") or []
    for r in rows:
        if (r.get("protocol") == protocol and r.get("a") == DEFAULT and r.get("b") == SEQSLAM
                and r.get("metric") == "R@1" and mode == "loop closure"):
            return f"{interval(r['difference'], r['lo'], r['hi'])}, {pair_word(r)}"
    return DASH


def frame_step(folder: Path) -> str:
    """The leaderboard's frame step as a protocol name: "leaderboard, every 8th frame" where the
    folder's targets.csv measured a step above 1 (its "frame step of the rows" target), else "leaderboard"."""
    rows = read_csv(folder / LB / "targets.csv") or []
    steps = [_float(r.get("measured")) for r in rows if r.get("protocol") == LEADERBOARD_PROTOCOL
             and str(r.get("target", "")).startswith("frame step")]
    step = next((int(x) for x in steps if x is not None), 1)
    return LEADERBOARD_PROTOCOL + (f", every {step}th frame" if step > 1 else "")


def _standing_row(folder: Path, protocol: str, label: str, mode: str, rows: dict) -> list[str]:
    """One standing row: ``protocol``'s ``mode`` (shown as ``label``), ``rows`` {method: leaderboard-shaped row}."""
    single = [r for m, r in rows.items() if m.endswith("(single frame)") and ":random" not in m]
    best = max(single, key=lambda r: _float(r.get("R@1_%")) or -1, default=None)
    d = rows.get(DEFAULT)
    return [provenance.dataset_name(folder) or folder.name, label, mode, (d or {}).get("queries", DASH),
            _r1(d), _r1(rows.get(CNN)), _r1(rows.get(SEQSLAM)),
            DASH if best is None else f"{_r1(best)} ({best['method'].replace(' (single frame)', '')})",
            _paired(folder, mode, protocol),
            DASH if d is None else interval(d.get("fps_median"), d.get("fps_min"), d.get("fps_max"))]


def standing_rows(folder: Path) -> list[list[str]]:
    """One row per protocol and mode: the leaderboard's (its frame step named), then each stream of
    target_protocols.csv (the targets' own protocols, e.g. Nordland at every frame): the named
    configurations, SeqSLAM tuned and the single-frame row with the highest R@1 point (ImageNet or
    hand-crafted; random-init rows left out; "–" in a protocol without single-frame rows)."""
    board = read_csv(folder / LB / "leaderboard.csv") or []
    out = [_standing_row(folder, LEADERBOARD_PROTOCOL, frame_step(folder), mode,
                         {r["method"]: r for r in board if r["mode"] == mode})
           for mode in dict.fromkeys(r["mode"] for r in board)]
    streams = read_csv(folder / LB / "target_protocols.csv") or []
    for protocol in dict.fromkeys(r["protocol"] for r in streams):
        mine = [r for r in streams if r["protocol"] == protocol]
        out += [_standing_row(folder, protocol, protocol, mode, {r["method"]: r for r in mine if r["mode"] == mode})
                for mode in dict.fromkeys(r["mode"] for r in mine)]
    return out


def standing(results_dirs) -> str:
    """Where greenloop's detector stands: one table over every folder, protocol and mode (README and
    summary.md), the paired rule under it."""
    rows = [r for d in map(Path, results_dirs) for r in standing_rows(d)]
    return table(STANDING, rows) + "\n" + goals.PAIRED_RULE + "\n"


def leaderboards(results_dirs) -> str:
    """Section 1: each folder's leaderboard tables and its named configurations' comparisons."""
    parts = ["\n## 1. Leaderboards\n\n",
             "Every row notebook 13 scored. R@1, AUC-PR, R@100P in % of the queries (R@1's 95 % interval in "
             "brackets); frames/s: median of the timing repeats [slowest, fastest]; closures at the row's "
             "threshold: closure precision = (declared − false) / declared, closure recall = "
             "(declared − false) / revisit queries (the share of revisit queries given a correct closure).\n"]
    for d in map(Path, results_dirs):
        parts += [f"\n### {name(d)}\n\n", leaderboard_section(d), "\n", comparisons_section(d)]
    return "".join(parts)


def spot_accuracy(folder: Path) -> tuple[dict | None, str]:
    """table1.csv's row for L = :data:`SPOT_FRAMES` frames per spot, and a note ('' when found)."""
    path = folder / T1 / "table1.csv"
    rows = read_csv(path)
    if rows is None:
        return None, missing(path)
    for r in rows:
        if _float(r.get("frames_per_spot")) == SPOT_FRAMES:
            return r, ""
    held = ", ".join(num(r.get("frames_per_spot")) for r in rows) or "none"
    return None, f"`{path.as_posix()}` has no row for L = {num(SPOT_FRAMES)} (its frames per spot: {held}).\n"


def main_paper_row(folder: Path) -> tuple[dict | None, str]:
    """The leaderboard's first row whose method starts with "main paper", and a note ('' when found)."""
    path = folder / LB / "leaderboard.csv"
    rows = read_csv(path)
    if rows is None:
        return None, missing(path)
    found = [r for r in rows if (r.get("method") or "").startswith(MAIN_PAPER)]
    return (found[0], "") if found else (None, f"`{path.as_posix()}` has no row whose method starts with "
                                                f"\"{MAIN_PAPER}\".\n")


def speed_row(folder: Path) -> tuple[dict | None, str]:
    """paper_vs_run.csv's "frames per second" row (columns paper, this run), and a note."""
    path = folder / SPEED / "paper_vs_run.csv"
    rows = read_csv(path)
    if rows is None:
        return None, missing(path)
    found = [r for r in rows if r.get("quantity") == "frames per second"]
    return (found[0], "") if found else (None, f"`{path.as_posix()}` has no \"frames per second\" row.\n")


def paper_detector_cells(folder: Path) -> tuple[list[str], str, dict]:
    """One dataset's row of section 2 (accuracy in %, tau in frames, closures, precision and recall
    in %, frames/s), its notes, and the paper's values its tables hold ({'acc': .., 'fps': ..})."""
    acc, n1 = spot_accuracy(folder)
    row, n2 = main_paper_row(folder)
    fps, n3 = speed_row(folder)
    acc, row, fps = acc or {}, row or {}, fps or {}
    accuracy = DASH if num(acc.get("acc_mean_%")) == DASH else (
        f"{num(acc.get('acc_mean_%'))} ± {num(acc.get('acc_std_%'))}; {num(acc.get('acc_median_converged_%'))}")
    accuracy = accuracy.removesuffix(f"; {DASH}")
    precision, recall = closure_rates(row)
    pair_p, pair_r = pair_rates(row.get("scored_on"))
    conv = convergence.spot_cnn_convergence(folder, T1, SPOT_FRAMES) if acc else None
    cells = [name(folder), accuracy, num(acc.get("seeds")), DASH if conv is None else conv.text(),
             num(row.get("threshold")), num(row.get("closures_declared")), num(row.get("closures_false")),
             percent(precision), percent(recall), num(pair_p), num(pair_r), num(fps.get("this run"))]
    return cells, n1 + n2 + n3, {"acc": num(acc.get("paper_acc_%")), "fps": num(fps.get("paper"))}


def paper_detector(results_dirs) -> str:
    """Section 2: the main paper's detector (spot CNN + dictionary at tau) per dataset, and a row
    "paper" with the paper's accuracy (L = 60) and frames/s as the folders' tables give them."""
    head = ["dataset", f"CNN accuracy, L = {num(SPOT_FRAMES)} (%, mean ± sd; median of the converged seeds)", "seeds", "converged", "τ",
            "closures declared", "closures false", "closure precision %", "closure recall %",
            "pair precision %", "pair recall %", "frames/s"]
    rows, notes, paper = [], "", {"acc": [], "fps": []}
    for d in map(Path, results_dirs):
        cells, note, ref = paper_detector_cells(d)
        rows.append(cells)
        notes += note
        for k, v in ref.items():
            if v != DASH and v not in paper[k]:
                paper[k].append(v)
    paper_cell = lambda k: " / ".join(paper[k]) or DASH
    rows.append(["paper"] + [paper_cell("acc")] + [DASH] * 9 + [paper_cell("fps")])
    return ("\n## 2. The main paper's detector as a loop-closure detector\n\n"
            "Accuracy: `01_spot_grouping/table1.csv` (the spot CNN's classification accuracy over its seeds; "
            f"converged, as the verdict counts it: {convergence.CONVERGED['spot CNN']}). "
            "τ and closures: the `13_leaderboard/leaderboard.csv` row whose method starts with "
            f"\"{MAIN_PAPER}\" (τ: its threshold, a count of frames classified as one spot; closure precision "
            "and recall as in section 1; pair precision and recall: its scored_on note's, over pairs of "
            "frames). frames/s: `06_speed/paper_vs_run.csv`, this run. The row \"paper\": the paper's values "
            "as those tables give them.\n\n"
            + table(head, rows) + ("\n" + notes if notes else "") + dictionary_seeds(results_dirs))


DICTIONARY_SEEDS = "05_dictionary_threshold/seeds_summary.csv"   # notebook 05's detector over each seed's CNN
DICTIONARY_VARIANT = "paper (spots by frame index)"               # its row on the paper's labels (05's VARIANTS[0])


def dictionary_seeds_row(folder: Path) -> dict | None:
    """The paper variant's row of :data:`DICTIONARY_SEEDS` (as written), or None without the table.
    Raises ValueError where the table has no such row."""
    rows = read_csv(Path(folder) / DICTIONARY_SEEDS)
    if rows is None:
        return None
    found = [r for r in rows if r.get("variant") == DICTIONARY_VARIANT]
    if not found:
        raise ValueError(f"{Path(folder) / DICTIONARY_SEEDS} has no row for the variant {DICTIONARY_VARIANT!r}: "
                         "rerun notebook 05, which writes one per variant")
    return found[0]


def dictionary_seeds(results_dirs) -> str:
    """Section 2's table of the dictionary over seeds, one row per folder with :data:`DICTIONARY_SEEDS`
    (seeds, converged seeds, closure precision and recall in %: median [min, max] over seeds, and the
    precision's median over the converged seeds, the statistic the verdict judges); "" where no folder has it."""
    rows = []
    for d in map(Path, results_dirs):
        r = dictionary_seeds_row(d)
        if r is not None:
            rows.append([name(d), num(r.get("seeds")), num(r.get("converged_seeds")),
                         interval(r.get("precision_median_%"), r.get("precision_min_%"), r.get("precision_max_%")),
                         num(r.get("precision_median_converged_%")),
                         interval(r.get("recall_median_%"), r.get("recall_min_%"), r.get("recall_max_%"))])
    if not rows:
        return ""
    head = ["dataset", "seeds", "converged", "closure precision % median [min, max]",
            "median of the converged seeds", "recall % median [min, max]"]
    return (f"\nThe dictionary over each seed's CNN (`{DICTIONARY_SEEDS}`, the paper's labels at notebook 05's τ; "
            "closure precision: true / flagged frames; the verdict judges the median of the converged seeds):\n\n"
            + table(head, rows))


def targets(results_dirs) -> str:
    """Section 3: each folder's targets.csv, every row (measured: % or frames/s as the target says)."""
    parts = ["\n## 3. The detector's targets\n\n",
             "Every row of each folder's `13_leaderboard/targets.csv` (greenloop.study.targets on the "
             "leaderboard and on each stream the targets name); met: – where the value was not measured, "
             "uninformative where it is a paired bound exactly 0 (the paired rule of section 1).\n"]
    for d in map(Path, results_dirs):
        path = d / LB / "targets.csv"
        rows = read_csv(path)
        parts.append(f"\n### {name(d)}\n\n")
        if rows is None:
            parts.append(missing(path))
            continue
        cells = [[r.get("protocol") or DASH, r.get("configuration") or DASH, r.get("target") or DASH,
                  num(r.get("measured")), r.get("required") or DASH, goals.met_word(r),
                  num(r.get("queries")), num(r.get("revisit_queries"))] for r in rows]
        parts += [f"From `{path.as_posix()}`.\n\n", table(TARGETS, cells)]
    return "".join(parts)


def machine(bench: Path) -> str:
    """Where the benchmark ran: the CPU of bench's manifest.json, or, without one, the ``Machine:``
    line scale.md's header holds (or a line saying neither says)."""
    if (bench / "manifest.json").is_file():
        return f"CPU (`{(bench / 'manifest.json').as_posix()}`): {provenance.row(bench)['CPU']}.\n"
    lines = (bench / "scale.md").read_text().splitlines() if (bench / "scale.md").is_file() else []
    said = [ln for ln in lines if ln.startswith("Machine:")]
    where = (f"; scale.md's header says:\n\n> {said[0]}\n" if said
             else "; nor does a scale.md there name the machine.\n")
    return f"`{bench.as_posix()}` holds no manifest.json" + where


def long_recordings(bench: Path, out: Path) -> str:
    """Section 4: a link to scale.md, the machine, and every row of scale_decisions.csv (times in ms,
    frames/s, % of frames, bytes per stored frame, seconds to preload), as scale.md writes them (.4g)."""
    scale, path = bench / "scale.md", bench / "scale_decisions.csv"
    parts = ["\n## 4. Long recordings\n\n"]
    if scale.is_file():
        link = Path(os.path.relpath(scale, out.parent)).as_posix()
        parts.append(f"The retrieval indexes and greenloop-seq's whole decision at 10^4..10^6 stored frames: "
                     f"[`{scale.as_posix()}`]({link}) (`make bench-scale`).\n\n")
    else:
        parts.append(missing(scale) + "\n")
    parts.append(machine(bench))
    rows = read_csv(path)
    if rows is None:
        return "".join(parts + ["\n", missing(path)])
    if not rows:
        return "".join(parts + [f"\n`{path.as_posix()}` holds no rows.\n"])
    cells = [[num(r.get(c), ".4g") for c in rows[0]] for r in rows]
    parts += [f"\nThe whole decision per frame with N frames stored, every row of `{path.as_posix()}` "
              f"(its columns as scale.md defines them):\n\n", table(list(rows[0]), cells)]
    return "".join(parts)


def markdown(results_dirs, out=None, bench=None) -> str:
    """summary.md's text for these results folders; ``out``: where it will be written (for the link
    to scale.md; default ``<first folder>/summary.md``); ``bench``: the benchmark folder (default
    ``<first folder>/bench``)."""
    first = Path(results_dirs[0])
    out, bench = Path(out or first / "summary.md"), Path(bench or first / "bench")
    return (header(results_dirs) + "\n## Where greenloop's detector stands\n\n" + standing(results_dirs)
            + leaderboards(results_dirs) + paper_detector(results_dirs)
            + targets(results_dirs) + long_recordings(bench, out))


def write_summary(results_dirs, out, bench=None, readme=None) -> Path:
    """Write :func:`markdown` of these results folders to ``out``, atomically, and refill the
    ``standing`` block of the Markdown file ``readme`` (when given) with :func:`standing`."""
    text = markdown(results_dirs, out, bench)
    written = write_atomic(Path(out), lambda p: p.write_text(text))
    if readme:
        fill_block(readme, "standing", standing(results_dirs))
    return written
