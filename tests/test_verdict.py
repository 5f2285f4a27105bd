"""The front page's verdicts (greenloop.study.verdict): each rule on planted tables, and the committed
README block and results/verdict.md equal what the module reads from the committed results."""
from pathlib import Path

import pandas as pd
import pytest

from greenloop.study import verdict

ROOT = Path(__file__).resolve().parents[1]
# the folders `make readme` reads (the Makefile's DATASET_RESULTS): results/ and every dataset folder beside it
FOLDERS = [ROOT / "results"] + sorted(p.parent for p in (ROOT / "results").glob("*/07_feature_baselines")
                                      if p.parent.name != "quick")


def table1(folder: Path, rows):
    """A 01_spot_grouping/table1.csv of (L, seeds, min, max, converged) rows."""
    (folder / "01_spot_grouping").mkdir(parents=True, exist_ok=True)
    pd.DataFrame([{"frames_per_spot": L, "seeds": n, "acc_mean_%": (lo + hi) / 2, "acc_std_%": 1.0,
                   "acc_min_%": lo, "acc_max_%": hi, "converged_seeds": c,
                   "paper_acc_%": {50: 97, 60: 98, 70: 97}.get(L)} for L, n, lo, hi, c in rows]
                 ).to_csv(folder / "01_spot_grouping" / "table1.csv", index=False)


@pytest.mark.parametrize("rows, accuracy, ranking", [
    ([(50, 5, 80, 85, 5), (60, 5, 97, 99, 5), (70, 5, 86, 90, 5)], verdict.HOLDS, verdict.HOLDS),
    ([(50, 5, 90, 99, 5), (60, 5, 80, 89, 5), (70, 5, 86, 88, 5)], verdict.FAILS, verdict.FAILS),
    ([(50, 5, 80, 92, 5), (60, 5, 90, 95, 5), (70, 5, 86, 90, 5)], verdict.FAILS, verdict.UNRESOLVED),
    ([(50, 3, 80, 85, 3), (60, 3, 97, 99, 3), (70, 3, 86, 90, 3)], verdict.HOLDS, verdict.UNRESOLVED),
    ([(50, 5, 30, 35, 0), (60, 5, 31, 36, 1), (70, 5, 29, 33, 0)], verdict.BUDGET, verdict.BUDGET),
])
def test_table1_value_and_order(tmp_path, rows, accuracy, ranking):
    table1(tmp_path, rows)
    assert verdict.table1_accuracy(tmp_path)[1] == accuracy
    assert verdict.table1_ranking(tmp_path)[1].startswith(ranking)


def test_an_order_on_fewer_than_five_seeds_is_never_resolved():
    arms = {"late": (3, 90, 95), "early": (3, 10, 20)}                  # far apart, but 3 seeds each
    assert verdict.rank_verdict("late", arms).startswith(verdict.UNRESOLVED)
    assert verdict.rank_verdict("late", {k: (5, *v[1:]) for k, v in arms.items()}) == verdict.HOLDS
    assert verdict.rank_verdict("early", {k: (5, *v[1:]) for k, v in arms.items()}) == verdict.FAILS


def test_an_order_of_siamese_networks_that_mostly_did_not_converge_is_budget_limited(tmp_path):
    """Xu 2022's orders read the converged_seeds of 10's tables: fewer than half of the arms' networks
    converged is budget-limited, whatever the seed ranges say."""
    (tmp_path / "10_siamese_rgbd").mkdir()
    def write(converged):
        pd.DataFrame([{"descriptor": f"scnn {x}, RGB", "supervision": x, "seeds": 5, "converged_seeds": c,
                       "AP_min": lo, "AP_max": hi} for x, lo, hi, c in zip(("softmax", "contrastive", "multitask"),
                                                                        (40, 30, 60), (50, 45, 70), converged)]
                     ).to_csv(tmp_path / "10_siamese_rgbd" / "supervisions.csv", index=False)
    write((5, 5, 5))
    assert verdict.xu_supervision(tmp_path)[1] == verdict.HOLDS                # [60, 70] above the others
    write((2, 2, 3))                                                           # 7 of 15 converged
    text, word = verdict.xu_supervision(tmp_path)
    assert word == verdict.BUDGET and text.endswith("7 of 15 networks converged")
    write((3, 2, 3))                                                           # 8 of 15: the ranges decide again
    assert verdict.xu_supervision(tmp_path)[1] == verdict.HOLDS


def test_the_dictionary_is_judged_by_closure_precision_and_reports_recall(tmp_path):
    (tmp_path / "13_leaderboard").mkdir()
    board = pd.DataFrame([{"method": "main paper: CNN + dictionary, tau = L + 10 = 70", "threshold": 70,
                           "closures_declared": 20, "closures_false": 1, "revisit_queries": 38, "scored_on": ""}])
    board.to_csv(tmp_path / "13_leaderboard" / "leaderboard.csv", index=False)
    text, word = verdict.dictionary(tmp_path)
    assert word == verdict.HOLDS and "19 of 20" in text and "recall 50 %" in text       # 19 / 38
    board.closures_false = 3                                                             # 85 % right
    board.to_csv(tmp_path / "13_leaderboard" / "leaderboard.csv", index=False)
    assert verdict.dictionary(tmp_path)[1] == verdict.FAILS


def test_a_folder_without_the_tables_reads_not_run(tmp_path):
    table = verdict.verdicts([tmp_path])
    assert len(table) == len(verdict.CLAIMS) and (table[tmp_path.name] == verdict.NOT_RUN).all()


def test_the_committed_verdicts_are_what_the_tables_say():
    expected = verdict.markdown(FOLDERS)
    readme = (ROOT / "README.md").read_text()
    block = readme.split("<!-- verdict:start -->\n", 1)[1].split("<!-- verdict:end -->", 1)[0]
    assert block == expected, "README's verdict block is stale: run `make readme`"
    assert expected in (ROOT / "results" / "verdict.md").read_text(), "results/verdict.md is stale: `make readme`"


def test_a_notebook_concludes_on_its_own_claims_for_its_dataset(tmp_path):
    table1(tmp_path, [(50, 5, 80, 85, 5), (60, 5, 97, 99, 5), (70, 5, 86, 90, 5)])
    text = verdict.conclusion(tmp_path, "01_spot_grouping")
    assert text.count("\n") == 1 and "97 / 98 / 97 %" in text and text.count(f"**{verdict.HOLDS}**") == 2
    assert f"**{verdict.NOT_RUN}**" in verdict.conclusion(tmp_path, "10_siamese_rgbd")   # no table: said so
    assert verdict.conclusion(tmp_path, "00_dataset") == ""


def test_coverage_says_whether_the_claim_holds_beside_whether_the_protocol_ran(tmp_path):
    from greenloop.study import coverage
    from greenloop.study import report as study_report
    table1(tmp_path, [(50, 5, 80, 85, 5), (60, 5, 97, 99, 5), (70, 5, 86, 90, 5)])
    t = study_report.coverage_with_claims([tmp_path]).set_index(["paper", "item"])
    cell = t.loc[(coverage.MAIN, "Table 1"), "claim holds"]
    assert cell.count(verdict.HOLDS) == 2 and "paper's accuracy" in cell                         # both Table 1 claims
    assert t.loc[(coverage.MAIN, "Table 3"), "claim holds"] == "a 1-pixel shift keeps the accuracy: "  # no table
    assert t.loc[(coverage.MAIN, "Fig. 1, Fig. 2"), "claim holds"] == ""              # no claim
    assert list(t.columns).index("claim holds") == list(t.columns).index("status") + 1


def test_an_order_whose_claimed_arm_did_not_run_reads_not_run():
    """Notebook 10 run with supervisions = ["softmax"]: the multi-task claim has no arm to judge."""
    assert verdict.rank_verdict("multitask", {"softmax": (5, 1.0, 2.0)}) == f"{verdict.NOT_RUN} (multitask not in this run)"


def test_qi_claims_name_the_row_that_is_missing(tmp_path):
    """07 without GhostNet and 09 without EfficientNet-Lite0 are not testable and say which row is
    absent, not "GhostNet AP nan %" or "no depth"."""
    for nb in ("07_feature_baselines", "09_rgbd_features"):
        (tmp_path / nb).mkdir()
    pd.DataFrame({"backbone": ["mobilenetv2"], "weights": ["imagenet"], "AP_pct": [80.0]}).to_csv(
        tmp_path / "07_feature_baselines" / "table2.csv", index=False)
    pd.DataFrame({"backbone": ["ghostnet"], "weights": ["random init"], "AP_RGB_pct": [50.0],
                  "AP_RGB-D_pct": [55.0]}).to_csv(tmp_path / "09_rgbd_features" / "rgbd.csv", index=False)
    text, word = verdict.qi_ranking(tmp_path)
    assert word == verdict.UNTESTABLE and "GhostNet not run" in text and "nan" not in text
    text, word = verdict.qi_depth(tmp_path)
    assert word == verdict.UNTESTABLE and "no EfficientNet-Lite0" in text
    pd.DataFrame({"backbone": ["efficientnetlite0"], "weights": ["imagenet"], "AP_RGB_pct": [50.0],
                  "AP_RGB-D_pct": [55.0]}).to_csv(tmp_path / "09_rgbd_features" / "rgbd.csv", index=False)
    assert verdict.qi_depth(tmp_path) == ("EfficientNet-Lite0 (ImageNet) AP 50 -> 55 %",
                                          verdict.UNRESOLVED + " (one AP each, no spread)")
