"""results/summary.md (greenloop.study.summary): the committed page is what the module writes from the
committed folders; a planted folder's closure precision and recall are (declared - false) / declared
and (declared - false) / revisit queries, every row shows, and a missing table gives a line, not an
exception."""
import csv
import json
from pathlib import Path

import pytest

from greenloop.cli import main as cli_main
from greenloop.study import summary

ROOT = Path(__file__).resolve().parents[1]
LB_COLUMNS = ["method", "mode", "queries", "revisit_queries", "R@1_%", "R@1_lo_%", "R@1_hi_%", "AUC-PR_%",
              "R@100P_%", "fps_median", "fps_min", "fps_max", "bytes_per_stored_frame", "threshold",
              "closures_declared", "closures_false", "scored_on"]
NOTE = "evaluation queries; frames 10..29 (16 revisit frames)"


def _csv(path: Path, columns, rows) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        w.writerows(rows)


def _planted(res: Path) -> Path:
    """A results folder with notebook 13's three tables, table1.csv and 06's paper_vs_run.csv."""
    lb = res / "13_leaderboard"
    _csv(lb / "leaderboard.csv", LB_COLUMNS, [
        ["greenloop-seq-grad", "loop closure", 20, 16, 75.0, 50.0, 90.0, 70.5, 30.0, 1000.5, 990.0, 1010.0,
         2088.0, 3.0, 10.0, 2.0, NOTE],
        ["pixels (single frame)", "loop closure", 20, 16, 40.0, 20.0, 60.0, 30.25, 5.0, 2000.0, 1900.0, 2100.0,
         4100.0, 0.9, 4.0, 3.0, NOTE],
        ["chance (random scores)", "loop closure", 20, 16, 1.52, "", "", 0.1, 0.02, "", "", "", "", "", "", "",
         NOTE],
        ["main paper: CNN + dictionary, tau = L + 10 = 70", "loop closure", 20, 16, "", "", "", "", "", 2148.7,
         2114.6, 2450.2, 0.0, 70.0, 8.0, 6.0, NOTE + "; decisions only (no score): pair precision 0.250, "
                                                     "recall 0.125"],
        ["greenloop-seq-grad", "place recognition", 20, 18, 95.0, 85.0, 100.0, 94.0, 60.0, 1000.5, 990.0, 1010.0,
         2088.0, "", "", "", NOTE]])
    _csv(lb / "comparisons.csv", ["protocol", "a", "b", "metric", "difference", "lo", "hi", "resolved", "queries"], [
        ["leaderboard", "greenloop-seq-grad", "pixels (single frame)", "R@1", 35.0, 10.5, 60.25, True, 20],
        ["leaderboard", "greenloop-seq-cnn", "pixels (single frame)", "AUC-PR", -1.5, -9.0, 4.0, False, 20],
        ["leaderboard", "greenloop-seq", "pixels (single frame)", "R@1", 12.0, 1.0, 20.0, True, 20]])
    _csv(lb / "targets.csv", ["protocol", "configuration", "target", "measured", "required", "met", "queries",
                              "revisit_queries"], [
        ["leaderboard", "greenloop-seq-grad", "frames/s (slowest repeat)", 990.0, ">= 920", True, "", ""],
        ["leaderboard", "greenloop-seq-grad", "closure precision at the threshold (%)", 80.0, ">= 90", False, 20, 16],
        ["night", "greenloop-seq-cnn", "R@1 (%), place recognition", "", ">= 90", "", 20, 18]])
    (lb / "manifest.json").write_text(json.dumps({"dataset": "data/planted-set", "cpu_model": "Planted CPU",
                                                  "date": "2026-01-02T03:04:05+00:00", "git_commit": "ab" * 20,
                                                  "git_dirty": False}))
    _csv(res / "01_spot_grouping" / "table1.csv", ["frames_per_spot", "seeds", "acc_mean_%", "acc_std_%",
                                                   "converged_seeds", "acc_median_converged_%", "paper_acc_%"],
         [[50, 5, 60.0, 4.0, 5, 61, 97], [60, 5, 91.5, 2.25, 3, 92, 98]])
    _csv(res / "06_speed" / "paper_vs_run.csv", ["quantity", "paper", "this run", "note"],
         [["seconds per 70-frame window", 0.076, "0.05", ""], ["frames per second", 920.0, "1500", ""]])
    return res


def _rows(text: str, first: str) -> list[list[str]]:
    """The cells of every markdown table row of ``text`` whose first cell is ``first``."""
    return [line.strip("| ").split(" | ") for line in text.splitlines() if line.startswith(f"| {first} |")]


def _section(text: str, number: int) -> str:
    return text.split(f"\n## {number}. ", 1)[1].split("\n## ", 1)[0]


def test_the_committed_summary_is_the_generated_one(monkeypatch):
    """results/summary.md is what `make summary` writes from the committed folders (the Makefile's
    DATASET_RESULTS: results, then results/*/ with notebook 07's folder, quick aside)."""
    monkeypatch.chdir(ROOT)
    dirs = ["results"] + sorted(p.parent.relative_to(ROOT).as_posix()
                                for p in (ROOT / "results").glob("*/07_feature_baselines") if p.parent.name != "quick")
    assert (ROOT / "results" / "summary.md").read_text() == summary.markdown(dirs, "results/summary.md"), (
        "results/summary.md is stale: make summary")


def test_a_planted_folder_gives_its_closure_rates_and_every_row(tmp_path, capsys):
    res = _planted(tmp_path / "results")
    out = tmp_path / "summary.md"
    assert cli_main(["summary", str(res), "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    text = out.read_text()
    assert "planted-set" in text and "Planted CPU" in text and "`abababababab`" in text
    board = _section(text, 1)
    grad = _rows(board, "greenloop-seq-grad")
    assert len(grad) == 2                                            # one per mode
    # declared 10, false 2, revisit queries 16: precision 8/10 = 80 %, recall 8/16 = 50 %
    assert grad[0] == ["greenloop-seq-grad", "20", "16", "75 [50, 90]", "70.5", "30", "1000.5 [990, 1010]",
                       "2088", "10", "2", "80", "50"]
    assert grad[1][1:3] == ["20", "18"] and grad[1][-4:] == ["–"] * 4   # place recognition: no closures
    # declared 4, false 3: precision 1/4 = 25 %, recall 1/16 = 6.25 %
    assert _rows(board, "pixels (single frame)")[0][-2:] == ["25", "6.25"]
    assert _rows(board, "chance (random scores)")[0][3:] == ["1.52", "0.1", "0.02"] + ["–"] * 6
    paper = _rows(board, "main paper: CNN + dictionary, tau = L + 10 = 70")[0]
    assert paper[-4:] == ["8", "6", "25", "12.5"]                      # 2/8 and 2/16
    assert f"- {NOTE} (3 rows)" in board and f"Scored on: {NOTE}." in board
    assert "pair precision 0.250, recall 0.125 (main paper" in board
    compared = _rows(board, "leaderboard")
    assert [r[1] for r in compared] == ["greenloop-seq-grad", "greenloop-seq-cnn"]   # a = greenloop-seq left out
    assert compared[0][4:] == ["35 [10.5, 60.25]", "resolved", "20"]
    assert compared[1][4:] == ["-1.5 [-9, 4]", "not resolved", "20"]
    detector = _rows(_section(text, 2), f"`{res.as_posix()}` (planted-set)")
    assert detector == [[f"`{res.as_posix()}` (planted-set)", "91.5 ± 2.25; 92", "5",
                         "3 of 5 seeds converged (epochs not recorded)", "70", "8", "6", "25",
                         "12.5", "25", "12.5", "1500"]]
    assert _rows(_section(text, 2), "paper") == [["paper", "98"] + ["–"] * 9 + ["920"]]
    goals = _section(text, 3)
    assert _rows(goals, "leaderboard") == [
        ["leaderboard", "greenloop-seq-grad", "frames/s (slowest repeat)", "990", ">= 920", "yes", "–", "–"],
        ["leaderboard", "greenloop-seq-grad", "closure precision at the threshold (%)", "80", ">= 90", "no", "20", "16"]]
    assert _rows(goals, "night") == [["night", "greenloop-seq-cnn", "R@1 (%), place recognition", "–", ">= 90", "–",
                                      "20", "18"]]
    bench = _section(text, 4)
    assert f"`{(res / 'bench' / 'scale.md').as_posix()}` is missing" in bench
    assert f"`{(res / 'bench' / 'scale_decisions.csv').as_posix()}` is missing" in bench


def test_the_rates_themselves():
    assert summary.closure_rates({"closures_declared": "10.0", "closures_false": "2.0",
                                  "revisit_queries": "16"}) == (80.0, 50.0)
    assert summary.closure_rates({"closures_declared": "10", "closures_false": "2"}) == (80.0, None)
    assert summary.closure_rates({"closures_declared": "", "closures_false": "", "revisit_queries": "16"}) == (
        None, None)
    assert summary.pair_rates("x; pair precision 0.217, recall 0.436") == (21.7, 43.6)
    assert summary.pair_rates("no pairs here") == (None, None)
    assert summary.num("260.0") == "260" and summary.num("83.33333333333333") == "83.3333"
    assert summary.num("") == "–" and summary.num("0.0351 (p95 0.0393)") == "0.0351 (p95 0.0393)"


def test_a_folder_without_its_tables_gives_missing_lines(tmp_path):
    bare = tmp_path / "bare"
    (bare / "13_leaderboard").mkdir(parents=True)
    text = summary.markdown([bare])
    assert f"`{(bare / '13_leaderboard' / 'leaderboard.csv').as_posix()}` is missing" in _section(text, 1)
    assert f"this folder has no `{(bare / '13_leaderboard' / 'comparisons.csv').as_posix()}`" in _section(text, 1)
    assert f"`{(bare / '01_spot_grouping' / 'table1.csv').as_posix()}` is missing" in _section(text, 2)
    assert f"`{(bare / '06_speed' / 'paper_vs_run.csv').as_posix()}` is missing" in _section(text, 2)
    assert f"`{(bare / '13_leaderboard' / 'targets.csv').as_posix()}` is missing" in _section(text, 3)
    assert _rows(_section(text, 2), f"`{bare.as_posix()}`") == [[f"`{bare.as_posix()}`"] + ["–"] * 11]
    planted = _planted(tmp_path / "results")
    (planted / "13_leaderboard" / "leaderboard.csv").unlink()          # beside a folder that has its tables
    text = summary.markdown([planted, bare])
    assert f"`{(planted / '13_leaderboard' / 'leaderboard.csv').as_posix()}` is missing" in text
    assert "| greenloop-seq-grad | pixels (single frame) | R@1 |" in text    # its comparisons still shown


def test_the_readme_standing_table_is_the_generated_one():
    root = Path(__file__).resolve().parents[1]
    dirs = [root / "results"] + sorted(p.parent for p in (root / "results").glob("*/07_feature_baselines")
                                       if p.parent.name != "quick")
    text = (root / "README.md").read_text()
    block = text.split("<!-- standing:start -->\n", 1)[1].split("<!-- standing:end -->", 1)[0]
    assert block == summary.standing(dirs), "README's standing table is stale: make readme"


def test_the_standing_shows_each_target_protocol_beside_the_leaderboard_and_words_its_pairs(tmp_path):
    """Nordland's leaderboard at every 8th frame stands beside its full-rate stream (target_protocols.csv),
    and a paired bound exactly on 0 reads uninformative, in the standing and in the targets."""
    res = _planted(tmp_path / "results")
    lb = res / "13_leaderboard"
    _csv(lb / "targets.csv", ["protocol", "configuration", "target", "measured", "required", "met"], [
        ["leaderboard", "greenloop-seq-grad", "frame step of the rows (1 = Nordland's full rate)", 8.0, "== 1", False],
        ["leaderboard", "greenloop-seq-grad", "R@1 above SeqSLAM (tuned) (9 %): the lowest low end of its paired "
         "differences (points)", 0.0, "> 0, each resolved", False]])
    _csv(lb / "target_protocols.csv", ["protocol"] + LB_COLUMNS, [
        ["every frame", "greenloop-seq-grad", "loop closure", 1768, 1768, 86.65, 80.65, 91.4, 86.2, 67.0, 829.9,
         820.1, 832.6, 2088.0, 3.0, 1339.0, 18.0, NOTE]])
    _csv(lb / "comparisons.csv", ["protocol", "a", "b", "metric", "difference", "lo", "hi", "resolved", "queries"], [
        ["leaderboard", "greenloop-seq-grad", "SeqSLAM (tuned)", "R@1", -22.39, -61.19, 0.0, False, 91],
        ["every frame", "greenloop-seq-grad", "SeqSLAM (tuned)", "R@1", 6.39, 1.74, 10.86, True, 1768]])
    rows = {(r[1], r[2]): r for r in summary.standing_rows(res)}
    assert rows[("leaderboard, every 8th frame", "loop closure")][8] == "-22.39 [-61.19, 0], uninformative"
    full = rows[("every frame", "loop closure")]
    assert full[4] == "86.65 [80.65, 91.4]" and full[8] == "6.39 [1.74, 10.86], resolved"
    assert full[9] == "829.9 [820.1, 832.6]"
    goals = _rows(_section(summary.markdown([res]), 3), "leaderboard")
    assert [g[5] for g in goals] == ["no", "uninformative"]


def test_section_2_shows_the_dictionary_over_seeds_where_notebook_05_wrote_them(tmp_path):
    """05's seeds_summary.csv (the paper's variant; the loop-aware one left out) gives one row per folder
    with its seeds, converged seeds, precision and recall median [min, max] and the converged median;
    a folder without it adds nothing (the committed page stays as it is)."""
    assert summary.dictionary_seeds([tmp_path]) == ""
    (tmp_path / "05_dictionary_threshold").mkdir()
    cols = "variant,seeds,converged_seeds,precision_median_%,precision_min_%,precision_max_%," \
           "precision_median_converged_%,recall_median_%,recall_min_%,recall_max_%\n"
    (tmp_path / summary.DICTIONARY_SEEDS).write_text(
        cols + f"{summary.DICTIONARY_VARIANT},5,4,80.5,60,95,82.25,42,40,44\nloop-aware (spots by place),5,5,99,99,99,99,90,90,90\n")
    text = summary.dictionary_seeds([tmp_path])
    assert text.count("\n| `") == 1 and "| 5 | 4 | 80.5 [60, 95] | 82.25 | 42 [40, 44] |" in text
    assert text in summary.paper_detector([tmp_path])
    (tmp_path / summary.DICTIONARY_SEEDS).write_text(cols + "loop-aware (spots by place),5,5,99,99,99,99,90,90,90\n")
    with pytest.raises(ValueError, match="no row for the variant"):
        summary.dictionary_seeds([tmp_path])
