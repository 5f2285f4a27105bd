"""Notebook 13's leaderboard rows: metrics, spreads, chance, closures, tables, the statement, the writes.

The detectors, their knobs and their tuning are registered in ``greenloop.methods`` (one entry
per family); ``greenloop.experiments.leaderboard`` runs them on one dataset under one tuning
budget (per-query AUC-PR on the tuning queries) and builds the tables with the functions here,
which know nothing of any one detector: a row is a method's (M, M) score matrix, its threshold,
its timing row and its meta (weights, knob text, bytes per stored frame).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import evaluate
from greenloop.datasets import sequence
from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.speed import timing
from greenloop.study import targets as goals
from greenloop.util.files import write_atomic

MODES = ("loop closure", "place recognition")
METRICS = ["R@1_%", "R@5_%", "AUC-PR_%", "R@100P_%", "R@95P_%"]
SPREADS = ["R@1_lo_%", "R@1_hi_%", "AUC-PR_lo_%", "AUC-PR_hi_%"]
COMPARED = ("R@1", "AUC-PR")                # the metrics the paired comparisons judge (:func:`paired`)
N_BOOT, SEED = 200, 0                       # the bootstrap's resamples and seed (:func:`resamples`), every interval
COMPARISON_COLUMNS = ["a", "b", "metric", "difference", "lo", "hi", "resolved", "queries"]
COUNTS = ["queries", "revisit_queries"]      # what each row's metrics rest on (:func:`query_counts`)
COLUMNS = (["method", "mode", "weights", "knobs"] + COUNTS + METRICS + SPREADS +
           ["pair_AP_%", "fps_median", "fps_min", "fps_max", "decode_ms", "bytes_per_stored_frame", "threshold",
            "closures_declared", "closures_false", "first_revisit_delay_frames", "scored_on"])


def weights_kind(label) -> str:
    """An ExtractInfo weights label -> "imagenet" | "random init" | "trained here" | "none"."""
    label = str(label)
    if label.startswith("imagenet"):
        return "imagenet"
    return label if label in ("random init", "trained here") else "none"


def reference_mask(frames, reference_frames) -> np.ndarray | None:
    """Place-recognition database: (M,) bool, described frames whose ORIGINAL index is below
    ``reference_frames`` (the first traversal), or None (loop-closure mode only)."""
    if reference_frames is None:
        return None
    ref = np.asarray(frames) < int(reference_frames)
    if ref.all() or not ref.any():
        raise ValueError(f"reference_frames={reference_frames} must split the described frames "
                         f"(original {int(np.min(frames))}..{int(np.max(frames))}) into a reference and queries")
    return ref











def query_counts(GT, exclude: int, queries, reference=None) -> dict:
    """How many queries a row rests on, from the masks its metrics use (``evaluate.candidate_mask``).

    GT: (M, M) bool; exclude: steps; queries: (M,) bool or None (every frame); reference: (M,)
    bool database (place recognition) or None (loop closure). Returns {"queries": the query
    frames in ``queries`` with at least one candidate (what every per-query metric averages
    over), "revisit_queries": those with a ground-truth partner among their candidates
    (``evaluate.revisit_queries``: what R@K and the recall of AUC-PR, R@100P rest on)}."""
    G = np.asarray(GT, dtype=bool)
    cand = evaluate.candidate_mask(len(G), exclude, queries, reference)
    rev = evaluate.revisit_queries(G, exclude, queries, reference)
    return {"queries": int(cand.any(0).sum()), "revisit_queries": int(rev.sum())}


def thresholds(S: dict, GT, exclude: int, tune, rule: str, fixed: dict | None = None) -> dict:
    """{method: threshold picked on the tuning queries (``seqmatch.choose_threshold``)}; NaN for
    every method when tune is None (no tuning part); a method in ``fixed`` ({method: threshold},
    e.g. the named default's ``fixed_threshold``) keeps that one."""
    fixed = fixed or {}
    return {k: (fixed[k] if k in fixed else seqmatch.choose_threshold(s, GT, exclude, queries=tune, rule=rule)
                if tune is not None else np.nan) for k, s in S.items()}


def metric_rows(S, GT, exclude: int, queries, reference=None, block: int = 10) -> list[dict]:
    """The metric columns of one score matrix, in % (unrounded): one row per database mode (loop closure;
    place recognition too when ``reference`` is given), with the :func:`query_counts` the row rests
    on and the :func:`spread` of R@1 and
    AUC-PR (bootstrap runs of ``block`` queries). pair_AP_% (pairs i < j, j - i > exclude) is a
    loop-closure quantity: NaN in the place-recognition row."""
    rows = []
    for mode, ref in (("loop closure", None), ("place recognition", reference)):
        if mode == "place recognition" and reference is None:
            continue
        q = evaluate.per_query(S, GT, exclude, queries=queries, reference=ref, ks=(1, 5))
        ap = evaluate.average_precision(S, GT, exclude, queries=queries) if ref is None else np.nan
        rows.append({"mode": mode, **query_counts(GT, exclude, queries, ref),
                     **{f"{k}_%": 100 * q[k] for k in ("R@1", "R@5", "AUC-PR", "R@100P", "R@95P")},
                     "pair_AP_%": 100 * ap, **spread(S, GT, exclude, queries, ref, block)})
    return rows


def spread(S, GT, exclude: int, queries, reference=None, block: int = 10, n_boot: int = N_BOOT,
           seed: int = SEED) -> dict:
    """95 % block-bootstrap intervals of R@1 and AUC-PR over the queries, in %.

    The per-query matches (``evaluate.best_matches``) are resampled by :func:`resamples` (runs of
    ``block`` consecutive queries: neighbouring queries see nearly the same frames) and each
    resample scored by ``evaluate.query_metrics`` (:func:`boot_metrics`). Returns {"R@1_lo_%",
    "R@1_hi_%", "AUC-PR_lo_%", "AUC-PR_hi_%"} (2.5th and 97.5th percentiles, in %, unrounded).
    """
    b = boot_metrics(evaluate.best_matches(S, GT, exclude, queries, reference, k=1), block, n_boot, seed)
    lo, hi = np.percentile(b, [2.5, 97.5], axis=0)
    return {"R@1_lo_%": 100 * lo[0], "R@1_hi_%": 100 * hi[0], "AUC-PR_lo_%": 100 * lo[1], "AUC-PR_hi_%": 100 * hi[1]}


def resamples(has_partner, block: int = 10, n_boot: int = N_BOOT, seed: int = SEED):
    """The block bootstrap's resamples of Q queries, the one definition :func:`spread` and
    :func:`paired` share. has_partner: (Q,) bool (``Matches.has_partner``). The queries are cut
    into runs of ``block`` consecutive ones; each resample draws as many runs with replacement
    (``np.random.default_rng(seed)``); one without a query with a partner is drawn again.
    Yields ``n_boot`` int index arrays into the Q queries (about Q long: the last run may be short)."""
    hp = np.asarray(has_partner, dtype=bool)
    runs = [np.arange(a, min(a + int(block), len(hp))) for a in range(0, len(hp), int(block))]
    rng, kept = np.random.default_rng(seed), 0
    while kept < n_boot:
        idx = np.concatenate([runs[i] for i in rng.integers(0, len(runs), len(runs))])
        if hp[idx].any():
            kept += 1
            yield idx


def boot_metrics(m, block: int = 10, n_boot: int = N_BOOT, seed: int = SEED) -> np.ndarray:
    """(n_boot, 2) float: R@1 and AUC-PR (fractions, :data:`COMPARED` order) of each of
    :func:`resamples` of the (Q,) matches ``m`` (``evaluate.Matches``), by ``evaluate.query_metrics``."""
    out = []
    for idx in resamples(m.has_partner, block, n_boot, seed):
        q = evaluate.query_metrics(evaluate.Matches(*(a[idx] for a in m[:6]), m.k), ks=(1,))
        out.append([q[k] for k in COMPARED])
    return np.array(out, dtype=np.float64).reshape(-1, len(COMPARED))


def resolved(lo, hi) -> bool:
    """A difference's interval [lo, hi] excludes 0."""
    return bool(lo > 0 or hi < 0)


def paired(a, b, block: int = 10, n_boot: int = N_BOOT, seed: int = SEED) -> dict:
    """Paired 95 % block bootstrap of method a minus method b over the same queries.

    a, b: ``evaluate.Matches`` of two methods on the same (Q,) queries (``best_matches`` with the
    same GT, exclude, queries, reference); both are scored on the SAME resamples (:func:`resamples`,
    as :func:`spread`: block, n_boot, seed). Returns {metric: {"difference": a - b on every query,
    "lo", "hi": 2.5th / 97.5th percentiles of the resampled differences, "resolved": [lo, hi]
    excludes 0}} for each metric of :data:`COMPARED`, in percentage points (unrounded)."""
    if not (np.array_equal(a.query, b.query) and np.array_equal(a.has_partner, b.has_partner)):
        raise ValueError("a paired comparison needs both methods' matches on the same queries and ground truth")
    return _differences(a, b, boot_metrics(a, block, n_boot, seed), boot_metrics(b, block, n_boot, seed))


def _differences(a, b, boot_a, boot_b) -> dict:
    """:func:`paired` from the matches and their (n_boot, 2) :func:`boot_metrics` on the same resamples."""
    qa, qb = (evaluate.query_metrics(m, ks=(1,)) for m in (a, b))
    lo, hi = np.percentile(100 * (boot_a - boot_b), [2.5, 97.5], axis=0)
    return {k: {"difference": 100 * (qa[k] - qb[k]), "lo": float(lo[i]), "hi": float(hi[i]),
                "resolved": resolved(lo[i], hi[i])} for i, k in enumerate(COMPARED)}


def comparison_pairs(board: pd.DataFrame, names) -> list[tuple]:
    """(a, b) for each of ``names`` with a loop-closure R@1 on the board against every other
    loop-closure row with one (chance and the decision-only rows have none), in board order."""
    lc = board[(board["mode"] == "loop closure") & ~board["method"].str.startswith("chance")].dropna(subset=["R@1_%"])
    rows = list(dict.fromkeys(lc["method"]))
    return [(a, b) for a in names if a in rows for b in rows if b != a]


def comparisons(S: dict, pairs, GT, exclude: int, queries, block: int = 10, n_boot: int = N_BOOT,
                seed: int = SEED) -> pd.DataFrame:
    """The paired comparisons (:func:`paired`, loop closure) of each (a, b) in ``pairs`` as they are
    written and judged: one row per pair and metric of :data:`COMPARED`, :data:`COMPARISON_COLUMNS`:
    difference, lo, hi (a minus b, percentage points, to 0.01), resolved (the written [lo, hi]
    excludes 0) and queries (Q, the queries both are scored on). S: {method: (M, M) score
    matrix}; GT, exclude, queries, block, n_boot, seed: as :func:`spread` (each method is
    bootstrapped once)."""
    names = list(dict.fromkeys(n for p in pairs for n in p))
    m = {n: evaluate.best_matches(S[n], GT, exclude, queries, k=1) for n in names}
    boot = {n: boot_metrics(m[n], block, n_boot, seed) for n in names}
    rows = []
    for a, b in pairs:
        for metric, d in _differences(m[a], m[b], boot[a], boot[b]).items():
            lo, hi = round(d["lo"], 2), round(d["hi"], 2)
            rows.append({"a": a, "b": b, "metric": metric, "difference": round(d["difference"], 2), "lo": lo,
                         "hi": hi, "resolved": resolved(lo, hi), "queries": len(m[a].query)})
    return pd.DataFrame(rows, columns=COMPARISON_COLUMNS)


PAIRED_COLUMNS = ["comparison", "a", "b", "metric", "difference", "low", "high", "queries", "block", "blocks",
                  "resolved", "result"]
TIE = goals.TIE                              # a paired interval of exactly [0, 0] (study.targets.paired_word)


def paired_table(S: dict, named_pairs, GT, exclude: int, queries, block: int = 10, n_boot: int = N_BOOT,
                 seed: int = SEED) -> pd.DataFrame:
    """Named paired comparisons of score matrices on the same queries, as notebooks 08 and 09 write
    them (``paired.csv``): :func:`comparisons` (the paired block bootstrap of the leaderboard, loop
    closure) with a name per pair and its verdict in words.

    S: {name: (M, M) score matrix}; named_pairs: [(comparison, a, b)], each a minus b; GT, exclude,
    queries, block, n_boot, seed: as :func:`spread` (queries None: every query). Returns a DataFrame
    of :data:`PAIRED_COLUMNS`, one row per pair and metric of :data:`COMPARED`: difference, low, high
    (a minus b and its 95 % interval, percentage points, to 0.01), queries (Q scored), block (queries
    per bootstrap run) and blocks (runs, ceil(Q / block)), resolved ([low, high] excludes 0) and
    result ("a above b", "b above a" with the arms' names, else the one word rule of paired intervals,
    ``study.targets.paired_word``: tie, uninformative or not resolved)."""
    named_pairs = list(named_pairs)
    if not named_pairs:
        return pd.DataFrame(columns=PAIRED_COLUMNS)
    names = {(a, b): c for c, a, b in named_pairs}
    t = comparisons(S, list(names), GT, exclude, queries, block, n_boot, seed).rename(columns={"lo": "low", "hi": "high"})
    t["comparison"] = [names[(a, b)] for a, b in zip(t.a, t.b)]
    t["block"], t["blocks"] = int(block), -(-t["queries"] // int(block))
    t["result"] = [goals.paired_word(lo, hi) if not r else f"{a} above {b}" if lo > 0 else f"{b} above {a}"
                   for a, b, lo, hi, r in zip(t.a, t.b, t.low, t.high, t.resolved)]
    return t[PAIRED_COLUMNS]


def paired_sentence(t: pd.DataFrame, comparison: str, metric: str = "AUC-PR") -> str:
    """One comparison of :func:`paired_table` (read back from paired.csv) in words: the difference
    in points with its paired interval, the queries and blocks, and "resolved: ..." or the word
    ``study.targets.paired_word`` gives an interval that holds 0; "" where the table lacks it."""
    rows = t[(t.comparison == comparison) & (t.metric == metric)]
    if not len(rows):
        return ""
    r = rows.iloc[0]
    tail = f"resolved: {r.result}" if r.resolved else f"{goals.paired_word(r.low, r.high)} (the interval holds 0)"
    return (f"{comparison}: {metric} {r.difference:+.2f} points [{r.low:+.2f}, {r.high:+.2f}] (paired bootstrap over "
            f"{int(r.queries)} queries in {int(r.blocks)} blocks of {int(r.block)}), {tail}")


def chance_rows(GT, exclude: int, queries, reference=None, scored_on: str = "") -> list[dict]:
    """The chance row(s): ``evaluate.query_chance`` per mode (pair AP: ``evaluate.chance_level``),
    on the same queries as the methods (``scored_on`` says which)."""
    rows = []
    for mode, ref in (("loop closure", None), ("place recognition", reference)):
        if mode == "place recognition" and reference is None:
            continue
        q = evaluate.query_chance(GT, exclude, queries=queries, reference=ref, ks=(1, 5))
        ap = evaluate.chance_level(GT, exclude, queries=queries) if ref is None else np.nan
        rows.append({"method": "chance (random scores)", "mode": mode, "weights": "none", "knobs": "-",
                     **query_counts(GT, exclude, queries, ref),
                     **{f"{k}_%": 100 * q[k] for k in ("R@1", "R@5", "AUC-PR", "R@100P", "R@95P")},
                     "pair_AP_%": 100 * ap, "scored_on": scored_on})
    return rows


def timing_methods(knobs: dict, dets: dict, describers: dict, descriptors: dict, start: int):
    """The :class:`greenloop.speed.timing.Method` list and preloads of every method.

    knobs: {method: knob record}; dets: {method: its streaming detector (``Entry.stream``)};
    describers: {method: frame -> descriptor (``Entry.describer``)}; descriptors: {descriptor: (N, D)}; start: the first
    timed frame of the stream (described index): frames 0..start-1 are preloaded.
    Returns (methods, preload).
    """
    methods, preload = [], {}
    for name, k in knobs.items():
        methods.append(timing.detector_method(name, dets[name], describers[name]))
        preload[name] = descriptors[k["descriptor"]][:start]
    return methods, preload


def closure_columns(S, GT, threshold, exclude: int, queries, frame_step: int) -> dict:
    """threshold, closures_declared, closures_false, first_revisit_delay_frames (ORIGINAL frames)
    of per-query closures at the threshold on the given queries (``seqmatch.closures``); None
    where the threshold is NaN (no tuning part)."""
    if threshold is None or not np.isfinite(threshold):
        return {"threshold": np.nan, "closures_declared": None, "closures_false": None,
                "first_revisit_delay_frames": None}
    c = seqmatch.closures(S, GT, threshold, exclude, queries=queries)
    return {"threshold": float(threshold), "closures_declared": c["declared"], "closures_false": c["false"],
            "first_revisit_delay_frames": None if c["first_delay"] is None else c["first_delay"] * int(frame_step)}


_NO_CLOSURES = {"threshold": np.nan, "closures_declared": None, "closures_false": None,
                "first_revisit_delay_frames": None}      # the streaming detectors run in loop-closure mode


def method_rows(S: dict, meta: dict, GT, exclude: int, evalq, reference, thr: dict, speed: dict,
                frame_step: int, scored_on: str, block: int = 10) -> list[dict]:
    """Every scored method's rows (one per mode). meta: {method: dict(weights, knobs,
    bytes_per_stored_frame)}; thr: thresholds; speed: {method: timing row + decode_ms}; block:
    the bootstrap run length of :func:`spread` (the notebook: its longest sequence). The
    threshold and closure columns are the streaming detector's, which runs in loop-closure mode:
    empty in place-recognition rows."""
    rows = []
    for name, s in S.items():
        sp = speed.get(name, {})
        common = {"method": name, **meta[name], "fps_median": sp.get("fps_median"), "fps_min": sp.get("fps_min"),
                  "fps_max": sp.get("fps_max"), "decode_ms": sp.get("decode_ms"), "scored_on": scored_on,
                  **closure_columns(s, GT, thr[name], exclude, evalq, frame_step)}
        rows += [{**common, **m, **(_NO_CLOSURES if m["mode"] == "place recognition" else {})}
                 for m in metric_rows(s, GT, exclude, evalq, reference, block)]
    return rows


def table(rows) -> pd.DataFrame:
    """The leaderboard DataFrame in :data:`COLUMNS` order, unrounded (:func:`rounded` is the
    written form); rows may lack columns (NaN/None)."""
    return pd.DataFrame(rows).reindex(columns=COLUMNS)


def rounded(board: pd.DataFrame) -> pd.DataFrame:
    """The leaderboard as it is written and judged (csv, Markdown, summary.json, the statement, the
    targets): the per-query metrics and pair AP to 0.01 and the threshold to 0.0001 (Python's
    ``round`` of each value), the bootstrap intervals to 0.01, frames/s to 0.1 and decode ms to
    0.01 (``DataFrame.round``)."""
    out = board.copy()
    for c, d in {**dict.fromkeys(METRICS + ["pair_AP_%"], 2), "threshold": 4}.items():
        out[c] = [v if pd.isna(v) else round(float(v), d) for v in out[c]]
    return out.round({**dict.fromkeys(SPREADS, 2), "fps_median": 1, "fps_min": 1, "fps_max": 1, "decode_ms": 2})


def pr_curves(S: dict, GT, exclude: int, queries) -> dict:
    """{method: (precision, recall)} per-query PR curves (loop-closure mode,
    ``evaluate.query_pr_curve``), for the figure."""
    return {k: evaluate.query_pr_curve(evaluate.best_matches(s, GT, exclude, queries, k=1))[:2] for k, s in S.items()}


def write(board: pd.DataFrame, out_dir, results_dir, title: str, note: str):
    """Write ``out_dir/leaderboard.csv`` and ``.md`` and the copy ``results_dir/leaderboard.csv``
    from ONE serialisation of the :func:`rounded` table (the same bytes, so the copy can never
    differ). Returns (csv path, md path, copy path)."""
    board = rounded(board)
    text = board.to_csv(index=False)
    out_dir, results_dir = Path(out_dir), Path(results_dir)
    paths = (out_dir / "leaderboard.csv", out_dir / "leaderboard.md", results_dir / "leaderboard.csv")
    md = f"### {title}\n\n" + board.to_markdown(index=False) + f"\n\n{note}\n"
    write_atomic(paths[0], lambda p: p.write_text(text))
    write_atomic(paths[1], lambda p: p.write_text(md))
    write_atomic(paths[2], lambda p: p.write_text(text))
    return paths


def _compare(a, b, lo: str, hi: str, word: tuple) -> str:
    """'faster than'/'slower than' (word) when the [lo, hi] ranges of rows a and b (frames/s [min,
    max] over the timing repeats) do not overlap, else 'not resolved against'."""
    if pd.isna(a[lo]) or pd.isna(b[lo]):
        return "not compared with"
    return word[0] if a[lo] > b[hi] else word[1] if a[hi] < b[lo] else "not resolved against"


def _pick(comparisons: pd.DataFrame, a: str, metric: str) -> pd.DataFrame:
    """The rows of the comparisons table (:func:`comparisons`) of ``a`` against any b on ``metric``."""
    return comparisons[(comparisons["a"] == a) & (comparisons["metric"] == metric)]


def paired_text(comparisons: pd.DataFrame, a: str, b: str, metric: str) -> str:
    """What the comparisons table says of a against b on ``metric``: "higher than it" / "lower than
    it" where its row is resolved (its interval above / below 0), else "not resolved", each with
    "(difference X [lo, hi])" in points; "not compared with it" where the table has no such row."""
    c = _pick(comparisons, a, metric)
    c = c[c["b"] == b]
    if not len(c):
        return "not compared with it"
    c = c.iloc[0]
    diff = f"(difference {c['difference']:.2f} [{c['lo']:.2f}, {c['hi']:.2f}])"
    if not c["resolved"]:
        return f"not resolved {diff}"
    return f"{'higher' if c['lo'] > 0 else 'lower'} than it {diff}"


def _tally(comparisons: pd.DataFrame, a: str) -> str:
    """'R@1 above k, below j, not resolved against r of the n other rows; AUC-PR ...' from the table."""
    out = []
    for metric in COMPARED:
        c = _pick(comparisons, a, metric)
        up, down = int((c["resolved"] & (c["lo"] > 0)).sum()), int((c["resolved"] & (c["hi"] < 0)).sum())
        out.append(f"{metric} above {up}, below {down}, not resolved against {len(c) - up - down} of the "
                   f"{len(c)} other rows")
    return "; ".join(out)


def _rivals(others: pd.DataFrame) -> list[str]:
    """The rows the statement sets a greenloop-seq row beside (those present, in this order): the
    highest R@1 of ``others``, the highest single-frame row, SeqSLAM published and tuned."""
    tops = [t["R@1_%"].idxmax() for t in (others, others[others.index.str.endswith("(single frame)")]) if len(t)]
    return list(dict.fromkeys(tops + [n for n in ("SeqSLAM (published)", "SeqSLAM (tuned)") if n in others.index]))


def statement(board: pd.DataFrame, comparisons: pd.DataFrame, seq_names=("greenloop-seq", "greenloop-seq-fast")) -> str:
    """What the table holds about the greenloop-seq rows, in sentences with the numbers (loop
    closure): R@1 and AUC-PR with their bootstrap intervals, frames/s as median [min, max]; how
    many other rows each is resolved above / below (:func:`_tally`); against each of
    :func:`_rivals` (chance and the greenloop-seq rows aside) "higher"/"lower" only where the
    comparisons table (:func:`comparisons`, paired differences in points) says resolved, else "not
    resolved (difference X [lo, hi])"; speed "faster" only where the [min, max] ranges do not overlap."""
    lc = board[board["mode"] == "loop closure"].set_index("method")
    others = lc[~lc.index.str.startswith(("greenloop-seq", "chance"))].dropna(subset=["R@1_%"])
    out = []
    for n in (s for s in seq_names if s in lc.index and pd.notna(lc.loc[s, "R@1_%"])):
        r = lc.loc[n]
        line = (f"{n}: R@1 {r['R@1_%']:.2f} % [{r['R@1_lo_%']:.2f}, {r['R@1_hi_%']:.2f}], AUC-PR {r['AUC-PR_%']:.2f} % "
                f"[{r['AUC-PR_lo_%']:.2f}, {r['AUC-PR_hi_%']:.2f}], R@100P {r['R@100P_%']:.2f} %")
        if pd.notna(r["fps_median"]):
            line += f", {r['fps_median']:.0f} frames/s [{r['fps_min']:.0f}, {r['fps_max']:.0f}]"
        line += f"; paired (comparisons): {_tally(comparisons, n)}"
        for b_name in _rivals(others):
            b = others.loc[b_name]
            line += (f"; vs {b_name} (R@1 {b['R@1_%']:.2f} %, AUC-PR {b['AUC-PR_%']:.2f} %; paired differences in "
                     f"points): R@1 {paired_text(comparisons, n, b_name, 'R@1')}, "
                     f"AUC-PR {paired_text(comparisons, n, b_name, 'AUC-PR')}")
            if pd.notna(r["fps_median"]) and pd.notna(b["fps_median"]):
                line += (f", speed {_compare(r, b, 'fps_min', 'fps_max', ('faster than', 'slower than'))} it "
                         f"({b['fps_median']:.0f} frames/s [{b['fps_min']:.0f}, {b['fps_max']:.0f}])")
        out.append(line)
    if "chance (random scores)" in lc.index:
        c = lc.loc["chance (random scores)"]
        out.append(f"chance: R@1 {c['R@1_%']:.2f} %, AUC-PR {c['AUC-PR_%']:.2f} %")
    return "\n".join(out)


def write_comparisons(table: pd.DataFrame, out_dir, note: str) -> tuple:
    """Write ``out_dir/comparisons.csv`` and ``.md`` (titled, with ``note``) from ONE table (the
    :func:`comparisons` rows as written, any extra columns first). Returns (csv path, md path)."""
    out_dir = Path(out_dir)
    paths = (out_dir / "comparisons.csv", out_dir / "comparisons.md")
    md = ("### Paired comparisons: a minus b on the same queries (percentage points)\n\n"
          + table.to_markdown(index=False) + f"\n\n{note}\n")
    write_atomic(paths[0], lambda p: p.write_text(table.to_csv(index=False)))
    write_atomic(paths[1], lambda p: p.write_text(md))
    return paths


def timing_window(evalq, n_frames: int):
    """(start, stop) described indices of the timed window: the first ``n_frames`` evaluation
    queries, so every frame before them (the revisit's first pass included) is stored. Without a
    tuning part (evalq all True) the last ``n_frames`` frames, the same rule for every method."""
    q = np.flatnonzero(np.asarray(evalq, dtype=bool))
    if not len(q):
        raise ValueError("no evaluation query to time")
    start = int(q[0]) if q[0] > 0 else max(len(evalq) - int(n_frames), 1)
    return start, min(start + int(n_frames), len(evalq))


def decode_window(paths, frames, start: int, stop: int):
    """The decoded frames ((H, W, 3) uint8 BGR, ``sequence.read_image``) of described frames start..stop-1
    and their paths; ValueError naming a frame that cannot be decoded."""
    sel = [paths[int(i)] for i in np.asarray(frames)[start:stop]]
    return [sequence.read_image(p) for p in sel], sel


def stream_checks(names, dets: dict, knobs: dict, descriptors: dict, S: dict, GT) -> dict:
    """{method: ``seqstream.stream_check``} over the whole stream (the revisit included) for the
    named sequence methods (thresholded detectors only)."""
    return {n: seqstream.stream_check(dets[n], descriptors[knobs[n]["descriptor"]], S[n], GT)
            for n in names if n in dets and dets[n].threshold is not None}


def targets(board: pd.DataFrame, names, comparisons: pd.DataFrame | None = None) -> dict:
    """{name: {"highest_R@1", "highest_AUC-PR" (above every other row but chance and greenloop-seq's,
    loop closure: with ``comparisons`` (:func:`comparisons`) every paired difference resolved above 0,
    ``study.targets.paired_ahead``; without, its 95 % interval wholly above theirs,
    ``study.targets.separated``), "fps_min_at_least_920" (the slowest repeat reaches the main paper's 920)}}."""
    lc = board[board["mode"] == "loop closure"].dropna(subset=["R@1_%"])
    out = {}
    for n in names:
        r = lc[lc.method == n]
        if not len(r):
            continue
        r, rest = r.iloc[0], lc[(lc.method != n) & ~lc.method.str.startswith(("greenloop-seq", "chance"))]
        above = {}
        for key in ("R@1_%", "AUC-PR_%"):
            if comparisons is not None:
                ok = goals.paired_ahead(comparisons, n, rest.to_dict("records"), key)[1]
            else:
                lo, top = goals.separated(r.to_dict(), rest.to_dict("records"), key)
                ok = lo is not None and top is not None and lo > top
            above[f"highest_{key[:-2]}"] = bool(ok)
        out[n] = {**above, "fps_min_at_least_920": bool(pd.notna(r["fps_min"]) and r["fps_min"] >= 920)}
    return out


def meta(knobs: dict, dets: dict, infos: dict, texts: dict) -> dict:
    """{method: dict(weights, knobs, bytes_per_stored_frame)} for :func:`method_rows`. infos:
    {descriptor: ExtractInfo} (SeqSLAM and the raw pixels: weights "none"); texts: {method: knob
    text}. Read the bytes after the detectors have stored a frame (after timing): a detector that
    stored none (one left out of the timing) gets None, not measured, rather than its 0."""
    return {k: {"weights": weights_kind(infos[kn["descriptor"]].weights) if kn["descriptor"] in infos else "none",
                "knobs": texts[k], "bytes_per_stored_frame": dets[k].bytes_per_frame or None} for k, kn in knobs.items()}


def knob_table(knobs: dict, score: dict, texts: dict) -> pd.DataFrame:
    """One row per method: its knob text and the tuning AUC-PR it was picked by (None: not tuned)."""
    return pd.DataFrame([{"method": k, "knobs": texts[k], "AUC-PR_tune_%": score.get(k)} for k in knobs])


def dictionary_row(name: str, tau: int, n_train: int, closures: dict, op: dict, speed: dict, frame_step: int,
                   scored_on: str, counts: dict | None = None) -> dict:
    """The dictionary's leaderboard row: decisions only (no per-query score, so no metric columns).
    closures: ``dictionary.query_closures``; op: ``evaluate.operating_point``; speed: its timing
    row with decode_ms; counts: :func:`query_counts` of the queries its closures are counted on
    (loop closure; None: not given)."""
    d = closures["first_delay"]
    return {"method": name, "mode": "loop closure", "weights": "trained here",
            "knobs": f"tau {tau}, CNN trained on original frames 0..{n_train - 1}", **(counts or {}),
            **{c: speed.get(c) for c in ("fps_median", "fps_min", "fps_max", "decode_ms")}, "bytes_per_stored_frame": 0,
            "threshold": tau, "closures_declared": closures["declared"], "closures_false": closures["false"],
            "first_revisit_delay_frames": None if d is None else d * int(frame_step),
            "scored_on": f"{scored_on}; decisions only (no score): pair precision {op['precision']:.3f}, recall {op['recall']:.3f}"}


def targets_table(board: pd.DataFrame, targets: str, frame_step: int,
                  comparisons: pd.DataFrame | None = None) -> pd.DataFrame:
    """The detector's targets for each named configuration on this board (``seqmatch.NAMED``: the named
    default always, the others where the board has their row), one row each: configuration, target,
    measured, required, met (``study.targets.detector_targets`` of the target set ``targets``, the
    dataset's ``Sequence.protocol.targets``, with the configuration's own seq_len; SeqSLAM = the
    published and the tuned row, each judged; "above" and "highest" from ``comparisons``,
    :func:`comparisons`, where given). A target measured on per-query rows gets their COUNTS
    (:func:`_rests_on`). Raises ValueError for a name that is none of ``study.targets.TARGET_SETS``."""
    names = [n for n in seqmatch.NAMED if n == seqmatch.DEFAULT_NAME or n in set(board["method"])]
    rows = [dict(configuration=n, **r, **_rests_on(board, n, r["target"])) for n in names
            for r in goals.detector_targets(board, targets, n, ("SeqSLAM (published)", "SeqSLAM (tuned)"),
                                            seq_len=seqmatch.NAMED[n][0]["seq_len"], frame_step=frame_step,
                                            comparisons=comparisons)]
    t = pd.DataFrame(rows)
    for c in COUNTS:                     # whole numbers, blank where not counted (not 203.0 beside NaN)
        t[c] = pd.Series([r[c] for r in rows], index=t.index, dtype=object)
    return t


def _rests_on(board: pd.DataFrame, method: str, target: str) -> dict:
    """COUNTS of ``method``'s board row that a target (its text, ``study.targets.detector_targets``)
    is measured on: the place-recognition row where the text names it, else the loop-closure row;
    None for the targets no query count bears on (frames/s, the frame step, frames of sequence:
    texts starting "frame") or where the board has no such row."""
    mode = "place recognition" if "place recognition" in target else "loop closure"
    row = board[(board["method"] == method) & (board["mode"] == mode)]
    if target.startswith("frame") or not len(row) or not set(COUNTS) <= set(row.columns):
        return dict.fromkeys(COUNTS)
    return {c: None if pd.isna(row[c].iloc[0]) else int(row[c].iloc[0]) for c in COUNTS}
