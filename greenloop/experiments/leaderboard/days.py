"""Notebook 13 on the greenhouse over days: every scored method's per-query R@1 split by where and when
the query was taken (``splits``), the counts behind every cell, and its figure. Only a dataset that is a
render of the days (``datasets.synthetic.daysmake.is_days``) has these splits; on any other
:func:`day_splits` returns None and notebook 13 writes nothing more.

The cells (rows of ``splits.csv``, loop closure, the leaderboard's evaluation queries and candidates):

    all / revisit queries            the queries with a pose-rule partner (what the leaderboard's R@1 rests on)
    day / within a day               revisit queries whose every partner was taken the same day
    day / across days                revisit queries with a partner taken on an earlier day
    direction / same direction       revisit queries on an aisle pass: the pose rule (Qi 2024 Eq. 5 < 0.5)
                                     admits at most 20.4 degrees between two views, so every partner of a
                                     revisit query looks the same way
    direction / opposite direction   queries on an aisle pass whose place was passed before only the other
                                     way: no pose-rule partner, but a candidate camera within REVERSE_M metres
                                     whose optical axis points more than 90 degrees away. A looser ground
                                     truth, position only: a hit is a best match within REVERSE_M metres,
                                     whatever its heading; every closure declared there is a false closure by
                                     the pose rule (they are counted in closures_false as well)
    light / <light>                  revisit queries taken on a day of that light (sun, overcast, night)
    query day / <day>                revisit queries taken on that day (the honest split's evaluation part
                                     is the later revisits, so the earlier days may hold none)
    all / evaluation queries         every evaluation query with a candidate, partner or not: where the
                                     false closures are counted

Columns: queries (the cell's queries), hits (best match a partner; in the opposite-direction cell a
camera within REVERSE_M metres), R@1_% (100 hits / queries; NaN in the evaluation-queries cell),
wrong_next_aisle (queries whose best match is no hit and whose camera stood in the aisle beside the
query's: the neighbouring aisle that looks the same), closures_declared / closures_false /
false_next_aisle (per-query closures at the method's threshold, as the leaderboard's closure columns:
declared where the best score reaches it, false where that match is no pose-rule partner, and how
many of those lie in the neighbouring aisle; empty where the method has no threshold).
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from greenloop import evaluate, report
from greenloop.datasets import sequence
from greenloop.datasets.synthetic import daysmake
from greenloop.datasets.synthetic.days import LIGHTS
from greenloop.methods.interface import Data

REVERSE_M = 1.0        # metres: the opposite-direction cell's position-only ground truth
COLUMNS = ["method", "split", "cell", "queries", "hits", "R@1_%", "wrong_next_aisle", "threshold",
           "closures_declared", "closures_false", "false_next_aisle"]
NO_DAYS = "not a render of the greenhouse over days: no per-day splits (splits.csv is written for those only)"
NOTE = ("leaderboard.days (module doc): loop closure on the leaderboard's evaluation queries and candidates. "
        "within / across days: all partners the same day / a partner on an earlier day; same direction: revisit "
        "queries on an aisle pass (the pose rule admits at most 20.4 degrees, so their partners look the same way); "
        f"opposite direction: aisle-pass queries with no pose-rule partner but a candidate within {REVERSE_M:g} m "
        "looking more than 90 degrees away, scored by position only (a hit: best match within "
        f"{REVERSE_M:g} m, any heading), its declared closures false by the pose rule; light: the query's day; "
        "wrong_next_aisle: best match no hit and in the aisle beside the query's; closures at each method's "
        "threshold (the leaderboard's), false_next_aisle: false closures in the neighbouring aisle; query day: the "
        "revisit queries of each day (the evaluation part is the later revisits: earlier days may hold none).")


class Frames(NamedTuple):
    """The described frames' places, (M,) arrays: day (index into lights), aisle (-1 outside),
    direction (+1 / -1, 0 outside), light (str per frame), name (the day's name per frame), t (M, 3)
    camera centres and axis (M, 3) optical axes, world frame, metres."""
    day: np.ndarray
    aisle: np.ndarray
    direction: np.ndarray
    light: np.ndarray
    name: np.ndarray
    t: np.ndarray
    axis: np.ndarray


def frames(dataset, described) -> Frames:
    """:class:`Frames` of the ``described`` (M,) original frame indices of a days folder
    (``daysmake.frame_places`` and its poses)."""
    p = daysmake.frame_places(dataset)
    poses = sequence.open(dataset).poses()[1][described]
    f = np.asarray(described)
    return Frames(p.day[f], p.aisle[f], p.direction[f], np.asarray(p.lights, dtype=object)[p.day[f]],
                  np.asarray(p.names, dtype=object)[p.day[f]], poses[:, :3, 3], poses[:, :3, 2])


def reverse_partners(places: Frames, queries: np.ndarray, cand: np.ndarray, radius: float = REVERSE_M) -> np.ndarray:
    """(Q,) bool: whether each query frame (``queries`` (Q,) indices) has a candidate (``cand`` (M, M)
    bool, [i, j]: i a candidate of j) whose camera stands within ``radius`` metres and whose optical
    axis points more than 90 degrees away from the query's."""
    out = np.zeros(len(queries), dtype=bool)
    for s in range(0, len(queries), 512):          # (M, 512) blocks: no (M, M) float matrix
        q = queries[s:s + 512]
        near = np.linalg.norm(places.t[:, None, :] - places.t[None, q, :], axis=2) < radius
        away = places.axis @ places.axis[q].T < 0
        out[s:s + 512] = (near & away & cand[:, q]).any(0)
    return out


def cells(places: Frames, GT, cand: np.ndarray) -> tuple[np.ndarray, dict]:
    """The queries and their cells (module doc). GT, cand: (M, M) bool ground truth and candidate mask
    (``evaluate.candidate_mask``: the leaderboard's evaluation queries and exclusion). Returns (queries
    (Q,) the frames with a candidate, as ``evaluate.best_matches`` orders them; {(split, cell): (Q,) bool})."""
    q = np.flatnonzero(cand.any(0))
    partners = (np.asarray(GT, dtype=bool) & cand)[:, q]
    rev = partners.any(0)
    earlier = (partners & (places.day[:, None] != places.day[q][None, :])).any(0)
    on_aisle = places.aisle[q] >= 0
    out = {("all", "revisit queries"): rev, ("day", "within a day"): rev & ~earlier,
           ("day", "across days"): rev & earlier, ("direction", "same direction"): rev & on_aisle,
           ("direction", "opposite direction"): on_aisle & ~rev & reverse_partners(places, q, cand)}
    out.update({("light", light): rev & (places.light[q] == light) for light in LIGHTS
                if (places.light == light).any()})
    out.update({("query day", name): rev & (places.name[q] == name) for name in dict.fromkeys(places.name)})
    out[("all", "evaluation queries")] = np.ones(len(q), dtype=bool)
    return q, out


def cell_queries(GT, exclude: int, evalq, places: Frames) -> pd.DataFrame:
    """How many queries each cell holds (split, cell, queries), whatever the method: the counts
    behind ``splits.csv`` without scoring anything. Arguments as :func:`splits`."""
    _, split = cells(places, GT, evaluate.candidate_mask(len(GT), exclude, evalq))
    return pd.DataFrame([{"split": k[0], "cell": k[1], "queries": int(v.sum())} for k, v in split.items()])


def next_aisle(places: Frames, m: evaluate.Matches) -> np.ndarray:
    """(Q,) bool: the best match's camera stood in the aisle beside the query's (both on an aisle)."""
    a, b = places.aisle[m.query], places.aisle[m.match]
    return (a >= 0) & (b >= 0) & (np.abs(a - b) == 1)


def method_rows(name: str, m: evaluate.Matches, split: dict, reverse_hit: np.ndarray, beside: np.ndarray,
                threshold) -> list[dict]:
    """One method's rows of ``splits.csv``: ``split`` from :func:`cells` (over ``m.query``), reverse_hit
    (Q,) bool: its best match within REVERSE_M metres (the opposite-direction cell's hits), ``beside``
    from :func:`next_aisle`, threshold its closure threshold (NaN or None: no closure columns)."""
    has_thr = threshold is not None and np.isfinite(threshold)
    declared = m.score >= threshold if has_thr else np.zeros(len(m.query), dtype=bool)
    false = declared & ~m.correct
    rows = []
    for key, mask in split.items():
        hit = reverse_hit if key == ("direction", "opposite direction") else m.correct
        n, h = int(mask.sum()), int((hit & mask).sum())
        scored = key != ("all", "evaluation queries")
        rows.append({"method": name, "split": key[0], "cell": key[1], "queries": n, "hits": h if scored else None,
                     "R@1_%": 100 * h / n if scored and n else np.nan,
                     "wrong_next_aisle": int((mask & ~hit & beside).sum()),
                     "threshold": float(threshold) if has_thr else np.nan,
                     **({"closures_declared": int((declared & mask).sum()), "closures_false": int((false & mask).sum()),
                         "false_next_aisle": int((false & mask & beside).sum())} if has_thr else
                        {"closures_declared": None, "closures_false": None, "false_next_aisle": None})})
    return rows


def splits(S: dict, GT, exclude: int, evalq, places: Frames, thresholds: dict) -> pd.DataFrame:
    """``splits.csv``: every method's rows (:func:`method_rows`), in ``S``'s order. S: {method: (M, M)
    score matrix}; GT: (M, M) bool; exclude: steps; evalq: (M,) bool evaluation queries; thresholds:
    {method: closure threshold, NaN where none}. The cells are the same for every method."""
    _, split = cells(places, GT, evaluate.candidate_mask(len(GT), exclude, evalq))
    rows = []
    for name, s in S.items():
        m = evaluate.best_matches(s, GT, exclude, queries=evalq, k=1)
        near = np.linalg.norm(places.t[m.match] - places.t[m.query], axis=1) < REVERSE_M
        rows += method_rows(name, m, split, near, next_aisle(places, m), thresholds.get(name))
    counts = ["queries", "hits", "wrong_next_aisle", "closures_declared", "closures_false", "false_next_aisle"]
    return pd.DataFrame(rows, columns=COLUMNS).astype({c: "Int64" for c in counts})


def day_splits(data: Data, tuned, timed) -> pd.DataFrame | None:
    """Notebook 13's splits on the days: :func:`splits` of every scored method (``tuned.S``) at its
    threshold (``timed.thresholds``) on the leaderboard's frames, ground truth, exclusion and evaluation
    queries; None where ``data.dataset`` is no render of the days (the notebook then writes nothing)."""
    if not daysmake.is_days(data.dataset):
        return None
    places = frames(data.dataset, data.frames)
    return splits(tuned.S, data.GT, data.exclude, data.evalq, places, timed.thresholds)


def write_splits(table: pd.DataFrame, out_dir) -> Path:
    """``splits.csv`` and ``splits.md`` in ``out_dir`` (R@1 to 2 decimals); returns the .md path."""
    return report.write_table(table, Path(out_dir) / "splits", columns={"R@1_%": 2, "threshold": 4},
                              title="R@1 split by day, direction and light; false closures in the neighbouring aisle",
                              note=NOTE)


def figure_splits(table: pd.DataFrame):
    """R@1 (%) of every method in each cell that has queries (module doc), one group of bars per cell
    labelled with its query count, methods coloured alike across cells: a Figure."""
    scored = table[table["R@1_%"].notna()]
    order = scored.drop_duplicates(["split", "cell"])[["split", "cell", "queries"]]
    methods = list(dict.fromkeys(scored.method))
    colours = report.palette(sorted(methods))
    width = 0.8 / max(1, len(methods))
    fig, ax = plt.subplots(figsize=(max(8, 1.3 * len(order)), 5))
    for k, name in enumerate(methods):
        r = scored[scored.method == name].set_index(["split", "cell"]).reindex(list(zip(order.split, order.cell)))
        ax.bar(np.arange(len(order)) + (k - (len(methods) - 1) / 2) * width, r["R@1_%"].to_numpy(float), width,
               color=colours[name], label=name)
    ax.set_xticks(np.arange(len(order)), [f"{c}\n({q} queries)" for c, q in zip(order.cell, order.queries)], fontsize=8)
    ax.set_ylabel("R@1 (%), loop closure, evaluation queries"); ax.set_ylim(0, 100)
    ax.set_title("R@1 by cell (opposite direction: best match within "
                 f"{REVERSE_M:g} m, any heading)", fontsize=9)
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1))
    fig.tight_layout()
    return fig
