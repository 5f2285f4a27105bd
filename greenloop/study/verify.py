"""Did a rerun reproduce the committed results? Compare two results folders table by table.

``python -m greenloop verify REFERENCE RERUN`` (``make verify RESULTS=RERUN [REFERENCE=results]``)
reads every ``*.csv`` under each notebook folder (``NN_name/``) of REFERENCE and the table of the
same path under RERUN, and compares them cell by cell:

* **timing is skipped**: a column whose name :func:`is_timing` (frames/s, fps, ms, us, s, seconds,
  time, duration, decode, speed-up, cpu, R_t: anything the machine or its load sets), and in a
  long table (a ``quantity`` / ``measurement`` / ``metric`` / ``target`` column naming each row) every
  cell of a row whose name :func:`is_timing`. The skipped columns and rows are printed per table.
* **numbers from trained models** may move within the committed seed spread (:func:`spread_band`):
  - in a per-seed table (a ``seed`` column) a number may lie anywhere in the committed range
    [min, max] of its column over the rows of the same group (same values in the columns left of
    ``seed`` and in every text column);
  - in a summary row (columns named ``*_mean``, ``*_median``, ``*_min``/``*_worst``, ``*_max``/
    ``*_best``, ``*_std``/``*_sd`` of one quantity) the mean, median, min and max may lie anywhere
    in the committed band [min, max] (without min/max: mean - std, mean + std), and the std within
    one committed std of its value. A mean or median with no band of its own takes the band of the
    quantity its name extends (``acc_median_converged_%`` that of ``acc_%``).
* **every other cell** exactly: text and integers as written, other numbers within a relative
  tolerance (``RTOL``, 1e-6; 1e-12 absolute around zero), NaN equal to NaN.

Each table prints one line: reproduced, differs (with the first differing cells), or missing (in
REFERENCE, not in RERUN; a table only in RERUN is listed as new and is not an error). The exit status
is 0 when every table reproduced, 1 when one differs or is missing, 2 for a usage error.

REFERENCE may be the folder of the rerun's dataset itself (``results/nordland``) or the folder above
the committed datasets (``results``): the rerun's manifests name its dataset, and ``results/<name>/``
(or ``results`` itself for the synthetic sequence, whose manifests name it) is its reference.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from greenloop.study import provenance

RTOL = 1e-6          # relative tolerance for non-integer numbers
ATOL = 1e-12         # absolute tolerance, for numbers around zero
SHOW = 5             # differing cells printed per table

# The one rule for what the machine or its load sets rather than the code and data: a column or a row
# name holding one of these words (words split at anything but a letter or digit; "'s" and "(an)other
# time", a revisit, dropped first). s, ms, us: a unit (train_s, decode_ms, "(s)", "frames/s");
# R_t: Qi 2024's time reduction against SIFT-BoVW, a ratio of times; cpu: the CPU's name or CPU time;
# cache: whether a model came from the on-disk cache (loaded_from_cache), which the cache's state sets.
TIMING_WORDS = (r"(ms|us|µs|s|sec|secs|seconds|per[ _]second|fps|hz|times?|timing|duration|decode"
                r"|speed[-_ ]?ups?|cpu|r_t|cache)")
_TIMING = re.compile(rf"(?<![a-z0-9]){TIMING_WORDS}(?![a-z0-9])")
_NOT_TIMING = re.compile(r"'s\b|other[ _]times?\b")
LABEL_COLUMNS = ("quantity", "measurement", "metric", "target")  # a long table's row names
SEED_COLUMN = "seed"
STATS = {"mean": "centre", "median": "centre", "min": "low", "worst": "low", "max": "high",
         "best": "high", "std": "spread", "sd": "spread"}


def is_timing(name) -> bool:
    """True when a column or row name says timing (or the machine): see TIMING_WORDS."""
    return bool(_TIMING.search(_NOT_TIMING.sub(" ", str(name).lower())))


def _number(text: str):
    """The cell's number (int for an integer literal, float otherwise, NaN for 'nan'), else None."""
    t = text.strip()
    if re.fullmatch(r"[+-]?\d+", t):
        return int(t)
    if not re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[+-]?(nan|inf)", t, re.IGNORECASE):
        return None
    return float(t)


def cells_equal(a: str, b: str, rtol: float = RTOL) -> bool:
    """Two cells as written in CSV: equal text, equal integers, or numbers within rtol (NaN == NaN)."""
    if a == b:
        return True
    x, y = _number(a), _number(b)
    if x is None or y is None:
        return False
    if isinstance(x, int) and isinstance(y, int):
        return x == y
    if math.isnan(x) or math.isnan(y):
        return math.isnan(x) and math.isnan(y)
    return math.isclose(x, y, rel_tol=rtol, abs_tol=ATOL)


def _stat(column: str):
    """(statistic kind, quantity) of a summary column: 'acc_mean_%' -> ('centre', 'acc_%'),
    'std' -> ('spread', ''); None for a column that names no single statistic."""
    words = column.split("_")
    hits = [i for i, w in enumerate(words) if w.lower() in STATS]
    if len(hits) != 1:
        return None
    i = hits[0]
    return STATS[words[i].lower()], "_".join(words[:i] + words[i + 1:])


def _finite(values) -> list[float]:
    """The values as floats when every one is a finite number; else []."""
    nums = [_number(v) for v in values]
    if any(n is None or math.isnan(n) for n in nums):
        return []
    return [float(n) for n in nums]


def _is_text(values) -> bool:
    """A column of words (not numbers, not True/False, not empty): a group key of a per-seed table."""
    return any(v not in ("", "True", "False") and _number(v) is None for v in values)


def _band(ref: pd.DataFrame, row: int, quantity: str):
    """(low, high) of one quantity's summary columns in a row: its min/worst and max/best, else
    mean - std and mean + std; None without either."""
    fam = {}
    for c in ref.columns:
        s = _stat(c)
        if s is not None and s[1] == quantity:
            kind = "mean" if s[0] == "centre" and "mean" in c.lower().split("_") else s[0]
            fam.setdefault(kind, c)
    val = {k: _finite([ref.iloc[row][c]]) for k, c in fam.items()}
    mu, sd = val.get("mean"), val.get("spread")
    lo = val.get("low") or ([mu[0] - sd[0]] if mu and sd else [])
    hi = val.get("high") or ([mu[0] + sd[0]] if mu and sd else [])
    return (lo[0], hi[0]) if lo and hi else None


def spread_band(ref: pd.DataFrame, row: int, column: str):
    """The committed seed spread a rerun's cell (row, column) may lie in: (low, high, why), or None
    where the table gives none (see the module's docstring for the rule)."""
    cols = list(ref.columns)
    seed = next((c for c in cols if c.lower() == SEED_COLUMN), None)
    if seed is not None and column != seed:
        keys = [c for c in cols if c != seed and (cols.index(c) < cols.index(seed) or _is_text(ref[c]))]
        group = ref[(ref[keys] == ref.iloc[row][keys]).all(axis=1)] if keys else ref
        vals = _finite(group[column])
        if len(vals) > 1:
            return min(vals), max(vals), f"committed range over {len(vals)} seeds"
    stat = _stat(column)
    if stat is None:
        return None
    kind, quantity = stat
    if kind == "spread":
        sd = _finite([ref.iloc[row][column]])
        return (0.0, 2 * sd[0], "committed std, +- itself") if sd else None
    own = _band(ref, row, quantity)
    if own is not None:
        return own + ("committed band",)
    if kind == "centre":          # a mean/median of a subset: the band of the quantity its name extends
        words = set(quantity.split("_"))
        for q in dict.fromkeys(s[1] for s in map(_stat, cols) if s is not None):
            b = _band(ref, row, q) if q != quantity and set(q.split("_")) - {""} <= words else None
            if b is not None:
                return b + (f"committed band of {q or 'the row'}",)
    return None


@dataclass
class TableResult:
    """One table's verdict: status 'reproduced' | 'differs' | 'missing' | 'new'."""
    table: str
    status: str
    skipped_columns: list = field(default_factory=list)
    skipped_rows: list = field(default_factory=list)
    within_spread: list = field(default_factory=list)
    differences: list = field(default_factory=list)
    note: str = ""

    @property
    def ok(self) -> bool:
        return self.status in ("reproduced", "new")

    def line(self, show: int = SHOW) -> str:
        out = f"{self.table}: {self.status}" + (f" ({self.note})" if self.note else "")
        if self.status == "differs":
            out += f" ({len(self.differences)} cells): " + "; ".join(self.differences[:show])
            if len(self.differences) > show:
                out += f"; … {len(self.differences) - show} more"
        notes = []
        if self.within_spread:
            notes.append(f"{len(self.within_spread)} cells within the committed seed spread")
        if self.skipped_columns:
            notes.append("timing columns skipped: " + ", ".join(self.skipped_columns))
        if self.skipped_rows:
            notes.append("timing rows skipped: " + ", ".join(repr(r) for r in self.skipped_rows))
        return out + "".join(f"\n    {n}" for n in notes)


def read_table(path) -> pd.DataFrame:
    """A CSV as written: every cell a string, empty cells empty, no type guessed."""
    return pd.read_csv(path, dtype=str, keep_default_na=False, na_filter=False)


def _cell(df, i, c):
    label = df.iloc[i, 0]
    return f"row {i + 1} ({df.columns[0]}={label!r}) {c}" if c != df.columns[0] else f"row {i + 1} {c}"


def compare_tables(ref_path, rerun_path, rtol: float = RTOL, name: str | None = None) -> TableResult:
    """Compare one reference table with the rerun's (see the module's docstring for the rules)."""
    name = name or str(ref_path)
    if not Path(rerun_path).is_file():
        return TableResult(name, "missing")
    ref, new = read_table(ref_path), read_table(rerun_path)
    res = TableResult(name, "reproduced")
    res.skipped_columns = [c for c in ref.columns if is_timing(c)]
    if list(ref.columns) != list(new.columns):
        gone = [c for c in ref.columns if c not in new.columns]
        added = [c for c in new.columns if c not in ref.columns]
        res.differences.append(f"columns differ (missing: {gone}, new: {added})" if gone or added
                               else f"columns in another order: {list(new.columns)}")
    if len(ref) != len(new):
        res.differences.append(f"{len(ref)} rows in the reference, {len(new)} in the rerun")
    if not res.differences:
        labels = [c for c in ref.columns if c.lower() in LABEL_COLUMNS]
        timing_rows = {i for i in range(len(ref)) for c in labels if is_timing(ref.iloc[i][c])}
        res.skipped_rows = [" / ".join(ref.iloc[i][c] for c in labels) for i in sorted(timing_rows)]
        for i in range(len(ref)):
            for c in ref.columns:
                a, b = ref.iloc[i][c], new.iloc[i][c]
                if c in res.skipped_columns or (i in timing_rows and c not in labels) or cells_equal(a, b, rtol):
                    continue
                band = spread_band(ref, i, c) if _number(b) is not None else None
                x = _number(b)
                if band is not None and not math.isnan(x) and band[0] - ATOL <= x <= band[1] + ATOL:
                    res.within_spread.append(f"{_cell(ref, i, c)}: {a} -> {b}")
                    continue
                why = f" (outside the {band[2]} {band[0]:g}..{band[1]:g})" if band else ""
                res.differences.append(f"{_cell(ref, i, c)}: reference {a!r}, rerun {b!r}{why}")
    if res.differences:
        res.status = "differs"
    return res


def notebook_tables(folder) -> list[Path]:
    """Every *.csv under each notebook folder (NN_name/) of a results folder, as relative paths."""
    folder = Path(folder)
    return sorted(p.relative_to(folder) for d in folder.glob("[0-9][0-9]_*") if d.is_dir()
                  for p in d.rglob("*.csv") if not p.name.startswith(".tmp"))


def resolve_reference(reference, rerun) -> Path:
    """The committed folder of the rerun's dataset: REFERENCE itself when its manifests name the same
    dataset (or either names none), else REFERENCE/<dataset>. Raises FileNotFoundError otherwise."""
    reference, rerun = Path(reference), Path(rerun)
    want, have = provenance.dataset_name(rerun), provenance.dataset_name(reference)
    if want is None or have is None or want == have:
        return reference
    sub = reference / want
    if provenance.dataset_name(sub) == want:
        return sub
    raise FileNotFoundError(f"{rerun} ran on {want}, {reference} holds {have} and no {sub} holds {want}'s "
                            f"committed results: name the reference folder of that dataset")


def compare_folders(reference, rerun, rtol: float = RTOL) -> list[TableResult]:
    """Every reference table against the rerun's, then the rerun's tables the reference lacks ('new')."""
    reference, rerun = Path(reference), Path(rerun)
    tables = notebook_tables(reference)
    if not tables:
        raise FileNotFoundError(f"{reference} holds no notebook tables (NN_name/*.csv)")
    out = [compare_tables(reference / t, rerun / t, rtol, name=t.as_posix()) for t in tables]
    for r in out:
        skipped = rerun / Path(r.table).parts[0] / "skipped.md"
        if r.status == "missing" and skipped.is_file():
            r.note = f"the notebook was not run: {skipped}"
    for t in notebook_tables(rerun):
        if t not in tables:
            out.append(TableResult(t.as_posix(), "new"))
    return out


def check(reference, rerun, rtol: float = RTOL) -> tuple[list[str], bool]:
    """Compare a rerun with the committed tables (:func:`compare_folders`, the reference resolved by
    :func:`resolve_reference`). Returns (the lines to print: a header, one per table, the counts,
    the verdict; whether every table was reproduced)."""
    reference = resolve_reference(reference, rerun)
    results = compare_folders(reference, rerun, rtol)
    lines = [f"reference {reference}, rerun {rerun}: timing columns and rows skipped, other numbers within rtol "
             f"{rtol:g} or the committed seed spread"] + [r.line() for r in results]
    count = {s: sum(r.status == s for r in results) for s in ("reproduced", "differs", "missing", "new")}
    ok = all(r.ok for r in results)
    return lines + [", ".join(f"{n} {s}" for s, n in count.items() if n or s == "reproduced"),
                    "reproduced" if ok else "NOT REPRODUCED"], ok
