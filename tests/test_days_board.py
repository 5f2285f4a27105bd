"""Notebook 13's splits and notebook 00's days on the greenhouse over days.

A tiny three-day render (two aisles, 160x120 every 0.25 m): day-00 sun, day-01 overcast, day-02 night
(the plan's night is its third day); aisle 1 is driven -z on day-00 and +z on day-01 and day-02. Scores
are planted by hand on the leaderboard's own ground truth, so every count the splits give is known.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from greenloop import evaluate, groundtruth
from greenloop.datasets import sequence
from greenloop.datasets.synthetic import daysmake, dayscene
from greenloop.datasets.synthetic.days import DaysHall, design_days, TINY_HALL
from greenloop.experiments import dataset as ds
from greenloop.experiments.leaderboard import days as board
from greenloop.experiments.leaderboard import rows as lb


@pytest.fixture(scope="module")
def three_days(tmp_path_factory):
    """(folder, described frames, exclude steps, GT, places) of the tiny three-day render at frame_step 1."""
    out = daysmake.make_greenhouse_days(tmp_path_factory.mktemp("days") / "tiny3", n_days=3, tiny=True, workers=1,
                                        progress=False)
    frames, ex, gt, _ = groundtruth.described_frames(out, 1, 0.5, sequence.open(out).exclude)
    return out, frames, ex, gt, board.frames(out, frames)


def _runs(values) -> list:
    """The values of consecutive runs, each once, in order."""
    v = list(values)
    return [x for k, x in enumerate(v) if k == 0 or x != v[k - 1]]


def test_aisle_at_reads_the_hall_geometry():
    h = DaysHall(n_aisles=3, bed_length=4.0)
    x, z = np.r_[h.aisle_x, h.aisle_x[1], h.side_x[0], h.aisle_x[0]], np.r_[[h.bed_z0 + 1] * 3, h.bed_z0 + 4.0, 6.0, 1.0]
    assert h.aisle_at(x, z).tolist() == [0, 1, 2, 1, -1, -1]       # the corridor and the cross aisle: none
    with pytest.raises(ValueError, match="one length"):
        h.aisle_at([1.0, 2.0], [1.0])


def test_frame_places_follow_each_days_route(three_days):
    """Each day's aisle passes, in driving order and direction, are its designed route."""
    out, *_ = three_days
    p = daysmake.frame_places(out)
    assert p.lights == ("sun", "overcast", "night") and p.names == ("day-00", "day-01", "day-02")
    assert p.offsets == (0, 4, 8) and p.hall == TINY_HALL
    for k, day in enumerate(design_days(3, TINY_HALL)):
        on = (p.day == k) & (p.aisle >= 0)
        assert _runs(zip(p.aisle[on], p.direction[on])) == [tuple(s) for s in day.route], day.name
    assert ((p.aisle >= 0) == (p.direction != 0)).all()
    with pytest.raises(FileNotFoundError, match="greenhouse-days"):
        daysmake.frame_places(out / "days")


def _first(places, day, aisle, direction=None, middle=False) -> int:
    """A described frame of ``day`` on ``aisle`` (its middle one when asked), in ``direction`` if given."""
    m = (places.day == day) & (places.aisle == aisle)
    if direction is not None:
        m &= places.direction == direction
    idx = np.flatnonzero(m)
    return int(idx[len(idx) // 2] if middle else idx[0])


def _planted(three_days):
    """Scores that make every revisit query's best match a non-partner (S = -GT: non-partners tie at 0
    and the first candidate, frame 0 in the side corridor, wins) except four planted queries: j1
    (day-01, aisle 0) and j2 (day-02, night, aisle 0) matched to a true partner on day-00; j3 (day-02,
    aisle 0) matched to day-00's camera in aisle 1, the neighbouring aisle; j4 (day-01's aisle 1, driven
    the other way than day-00) matched to day-00's nearest camera on aisle 1 (a reverse revisit)."""
    _, _, ex, gt, places = three_days
    S = -gt.astype(np.float64)
    j1 = _first(places, 1, 0, middle=True)
    i1 = int(np.flatnonzero(gt[:, j1] & (places.day == 0))[0])
    j2 = _first(places, 2, 0, middle=True)
    i2 = int(np.flatnonzero(gt[:, j2] & (places.day == 0))[0])
    j3 = _first(places, 2, 0, middle=False) + 2
    assert gt[:, j3].any()
    i3 = _first(places, 0, 1, middle=True)
    j4 = _first(places, 1, 1, middle=True)
    on1 = np.flatnonzero((places.day == 0) & (places.aisle == 1))
    i4 = int(on1[np.argmin(np.linalg.norm(places.t[on1] - places.t[j4], axis=1))])
    for i, j in ((i1, j1), (i2, j2), (i3, j3), (i4, j4)):
        S[i, j] = 1.0
    return S, (j1, j2, j3, j4)


def test_splits_count_the_planted_queries(three_days):
    _, _, ex, gt, places = three_days
    S, (j1, j2, j3, j4) = _planted(three_days)
    assert not gt[:j4, j4].any()                          # nothing before it by the pose rule
    evalq = np.ones(len(gt), dtype=bool)
    t = board.splits({"planted": S, "no threshold": S}, gt, ex, evalq, places, {"planted": 0.5, "no threshold": np.nan})
    c = t[t.method == "planted"].set_index(["split", "cell"])
    rev = lb.query_counts(gt, ex, evalq)["revisit_queries"]
    assert c.loc[("all", "revisit queries"), "queries"] == rev and c.loc[("all", "revisit queries"), "hits"] == 2
    # the leaderboard's own R@1 on the same matrix
    assert c.loc[("all", "revisit queries"), "R@1_%"] == pytest.approx(100 * evaluate.per_query(S, gt, ex, evalq)["R@1"])
    # j1 and j2 revisit day-00's aisle 0 on later days: across days, one under overcast, one under night
    assert c.loc[("day", "across days"), "hits"] == 2 and c.loc[("day", "within a day"), "hits"] == 0
    assert (c.loc[("day", "across days"), "queries"] + c.loc[("day", "within a day"), "queries"]) == rev
    assert c.loc[("light", "overcast"), "hits"] == 1 and c.loc[("light", "night"), "hits"] == 1
    assert c.loc[("light", "sun"), "queries"] == 0            # day-00 revisits nothing before it
    assert [c.loc[("query day", d), "hits"] for d in ("day-00", "day-01", "day-02")] == [0, 1, 1]
    nights = int((places.light[np.flatnonzero(gt.any(0))] == "night").sum())
    assert c.loc[("light", "night"), "queries"] <= nights and c.loc[("light", "night"), "queries"] > 0
    # j3's match stood in the neighbouring aisle: a wrong best match and a false closure there, the only ones
    assert c.loc[("all", "revisit queries"), "wrong_next_aisle"] == 1
    assert c.loc[("all", "evaluation queries"), "false_next_aisle"] == 1
    # j4: the other way on aisle 1, no pose-rule partner; its match within 1 m is a position-rule hit, and
    # the closure declared there is false by the pose rule
    rv = c.loc[("direction", "opposite direction")]
    assert rv.hits == 1 and rv.closures_declared == 1 and rv.closures_false == 1 and rv.queries > 1
    assert c.loc[("all", "evaluation queries"), ["closures_declared", "closures_false"]].tolist() == [4, 2]
    # the same direction cell holds revisit queries on an aisle: j1, j2 (hits), j3 (miss)
    assert c.loc[("direction", "same direction"), "hits"] == 2
    counts = board.cell_queries(gt, ex, evalq, places).set_index(["split", "cell"]).queries
    assert (counts == c.queries.reindex(counts.index)).all()       # the counts without scoring anything
    n = t[t.method == "no threshold"]
    assert n.closures_declared.isna().all() and n.threshold.isna().all()
    assert (n["R@1_%"].fillna(-1).values == c["R@1_%"].fillna(-1).values).all()


def test_day_splits_only_on_a_days_render(tiny_sequence, three_days, tmp_path):
    assert board.day_splits(SimpleNamespace(dataset=sequence.open(tiny_sequence)), None, None) is None
    out, frames, ex, gt, _ = three_days
    S, _ = _planted(three_days)
    data = SimpleNamespace(dataset=sequence.open(out), frames=frames, GT=gt, exclude=ex, evalq=np.ones(len(gt), bool))
    t = board.day_splits(data, SimpleNamespace(S={"planted": S}), SimpleNamespace(thresholds={"planted": 0.5}))
    md = board.write_splits(t, tmp_path)
    assert md.name == "splits.md" and "20.4 degrees" in md.read_text()
    assert (tmp_path / "splits.csv").read_text().count("planted") == len(t) == 12
    assert board.figure_splits(t) is not None


def test_same_place_frames_show_each_day(three_days):
    out, *_ = three_days
    t = ds.same_place_frames(out)
    assert t.place.tolist() == ["aisle 0"] * 3 + ["aisle 1"] * 3 and t.day.tolist() == ["day-00", "day-01", "day-02"] * 2
    p = daysmake.frame_places(out)
    assert (p.day[t.frame] == [0, 1, 2] * 2).all() and (p.aisle[t.frame] == [0] * 3 + [1] * 3).all()
    assert (t.distance_m < 0.3).all()                      # the same place, one frame spacing at most
    # aisle 1 is driven the other way on day-01 and day-02
    assert t.same_direction.tolist() == [True, True, True, True, False, False]
    assert ds.figure_days(out, t) is not None


def test_renderer_scope_is_the_renderers_constant():
    text = ds.renderer_scope()
    assert all(x in text for x in dayscene.MODELLED + dayscene.NOT_MODELLED)
    assert {"shadows", "motion blur", "rolling shutter"} <= set(dayscene.NOT_MODELLED)
    assert any(x.startswith("wind") for x in dayscene.NOT_MODELLED)
