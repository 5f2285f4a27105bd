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


def table1(folder: Path, rows, median=None):
    """A 01_spot_grouping/table1.csv of (L, seeds, min, max, converged) rows; the converged seeds'
    median is ``median`` (default: the middle of min and max)."""
    (folder / "01_spot_grouping").mkdir(parents=True, exist_ok=True)
    pd.DataFrame([{"frames_per_spot": L, "seeds": n, "acc_mean_%": (lo + hi) / 2, "acc_std_%": 1.0,
                   "acc_min_%": lo, "acc_max_%": hi, "final_train_acc_min_%": 99.0, "converged_seeds": c,
                   "acc_median_converged_%": (median or (lo + hi) / 2) if c else float("nan"),
                   "paper_acc_%": {50: 97, 60: 98, 70: 97}.get(L)} for L, n, lo, hi, c in rows]
                 ).to_csv(folder / "01_spot_grouping" / "table1.csv", index=False)


@pytest.mark.parametrize("rows, accuracy, ranking", [
    ([(50, 5, 80, 85, 5), (60, 5, 97, 99, 5), (70, 5, 86, 90, 5)], verdict.HOLDS, verdict.HOLDS),
    ([(50, 5, 90, 99, 5), (60, 5, 80, 89, 5), (70, 5, 86, 88, 5)], verdict.FAILS, verdict.FAILS),
    ([(50, 5, 80, 92, 5), (60, 5, 90, 95, 5), (70, 5, 86, 90, 5)], verdict.FAILS, verdict.UNRESOLVED),
    ([(50, 3, 80, 85, 3), (60, 3, 97, 99, 3), (70, 3, 86, 90, 3)], verdict.UNRESOLVED, verdict.UNRESOLVED),
    ([(50, 5, 30, 35, 0), (60, 5, 31, 36, 1), (70, 5, 29, 33, 0)], verdict.BUDGET, verdict.BUDGET),
])
def test_table1_value_and_order(tmp_path, rows, accuracy, ranking):
    table1(tmp_path, rows)
    assert verdict.table1_accuracy(tmp_path)[1].startswith(accuracy)
    assert verdict.table1_ranking(tmp_path)[1].startswith(ranking)


def test_a_value_reached_by_the_best_seed_only_does_not_hold(tmp_path):
    """The paper's 98 % reached by one seed (max 99) while the converged seeds' median is 92: the
    rule judges the median, shown in the cell, never the best seed."""
    table1(tmp_path, [(60, 5, 90, 99, 5)], median=92)
    text, word = verdict.table1_accuracy(tmp_path)
    assert word == verdict.FAILS and "median of the converged seeds 92" in text and "[90, 99]" in text
    table1(tmp_path, [(60, 5, 90, 99, 5)], median=98)
    assert verdict.table1_accuracy(tmp_path)[1] == verdict.HOLDS


def test_the_rules_printed_are_the_rules_judged():
    """The rule text comes from the constants the readers judge by."""
    assert f"fewer than {verdict.MIN_SEEDS} trained seeds" in verdict.RULES
    assert f"reach {verdict.DICTIONARY_PRECISION:g} %" in verdict.RULES
    assert f"reached {verdict.CONVERGED_AT} %" in verdict.RULES and "never the best seed" in verdict.RULES
    assert all(f"{k}: {v}" in verdict.RULES for k, v in verdict.CONVERGED.items())


@pytest.mark.parametrize("lo, hi, word", [(1.74, 10.86, verdict.HOLDS), (-9.0, -0.5, verdict.FAILS),
                                          (0.0, 0.0, f"{verdict.UNRESOLVED} (tie)"),
                                          (-61.19, 0.0, f"{verdict.UNRESOLVED} (uninformative)"),
                                          (0.0, 78.05, f"{verdict.UNRESOLVED} (uninformative)"),
                                          (-5.43, 8.64, f"{verdict.UNRESOLVED} (the paired interval holds 0)")])
def test_a_paired_order_calls_a_tie_a_tie_and_a_bound_on_zero_uninformative(lo, hi, word):
    """A ten-block bootstrap's bound landing on exactly 0 resolves nothing, either way; the rule is printed."""
    assert verdict.paired_verdict(lo, hi) == word
    assert "(tie) where both ends are exactly 0" in verdict.RULES and "(uninformative)" in verdict.RULES


def spot_cnn_run(folder: Path, converged=(True,) * 5, epochs=200, dictionary_rows=1, precision=95.0):
    """02's per_seed.csv (seed 4 stopped early at 80 % training accuracy: converged by the flag), 03's
    errors, 04's table3 and 13's dictionary rows, with 02's and 13's manifests (same L, epochs)."""
    for nb in ("02_training_over_seeds", "03_confusion_matrix", "04_shift_robustness", "13_leaderboard"):
        (folder / nb).mkdir(parents=True, exist_ok=True)
        (folder / nb / "manifest.json").write_text(
            '{"parameters": {"frames_per_spot": 60, "epochs": %d}}' % epochs)
    acc = [90.0, 91.0, 92.0, 93.0, 99.0]
    pd.DataFrame({"split": "random", "seed": range(5), "test_acc_%": acc, "min_val_acc_after_ep45_%": acc,
                  "final_train_acc_%": [99, 99, 99, 99, 80], "converged": list(converged)}
                 ).to_csv(folder / "02_training_over_seeds" / "per_seed.csv", index=False)
    pd.DataFrame({"split": "random", "seed": range(5), "test_frames": 100, "misclassified": [10, 9, 8, 7, 1]}
                 ).to_csv(folder / "03_confusion_matrix" / "errors_per_seed.csv", index=False)
    pd.DataFrame({"seed": range(5), "original_test_%": acc, "shift1_all_frames_%": acc,
                  "shift1_test_only_%": [a - 10 for a in acc]}).to_csv(folder / "04_shift_robustness" / "table3.csv",
                                                                       index=False)
    declared = 100
    pd.DataFrame([{"method": "main paper: CNN + dictionary, tau = L + 10 = 70", "threshold": 70,
                   "closures_declared": declared, "closures_false": declared - precision, "revisit_queries": 200,
                   "scored_on": ""}] * dictionary_rows).to_csv(folder / "13_leaderboard" / "leaderboard.csv", index=False)


def test_an_early_stopped_seed_is_counted_once_the_same_in_every_row_of_its_family(tmp_path):
    """Seed 4 stopped early (80 % training accuracy, converged by the printed definition): every row
    on 02's models counts it, and its value enters each median, in one wording."""
    spot_cnn_run(tmp_path)
    cells = [verdict.learning_curves(tmp_path)[0], verdict.confusion(tmp_path)[0], verdict.shift(tmp_path)[0],
             verdict.dictionary(tmp_path)[0]]
    assert all(c.count("5 of 5 seeds converged (200 epochs") == 1 for c in cells)
    assert "median of the converged seeds 92 %" in cells[0]            # 90, 91, 92, 93, 99
    spot_cnn_run(tmp_path, converged=(True, True, False, False, False))
    words = [f(tmp_path)[1] for f in (verdict.learning_curves, verdict.confusion, verdict.shift, verdict.dictionary)]
    assert words == [verdict.BUDGET] * 4
    assert all("2 of 5 seeds converged" in f(tmp_path)[0]
               for f in (verdict.learning_curves, verdict.confusion, verdict.shift))


def test_the_shift_row_is_judged_on_held_out_frames(tmp_path):
    spot_cnn_run(tmp_path)
    text, word = verdict.shift(tmp_path)
    assert "held-out frames shifted: median of the converged seeds 82 %" in text and "(unshifted 92 %)" in text
    assert word == verdict.FAILS                                      # 82 < 92, though the unshifted 92 reaches


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


def test_the_dictionary_is_judged_by_its_printed_precision_rule_and_its_cnn_convergence(tmp_path):
    spot_cnn_run(tmp_path, dictionary_rows=1)                              # one CNN seed: no spread
    text, word = verdict.dictionary(tmp_path)
    assert word.startswith(verdict.UNRESOLVED) and "1 CNN seed, no spread" in text and "95 of 100" in text
    assert "recall 47.5 %" in text                                          # 95 / 200
    spot_cnn_run(tmp_path, dictionary_rows=5)
    assert verdict.dictionary(tmp_path)[1] == verdict.HOLDS                 # median 95 >= 90
    spot_cnn_run(tmp_path, dictionary_rows=5, precision=85.0)
    assert verdict.dictionary(tmp_path)[1] == verdict.FAILS
    spot_cnn_run(tmp_path, dictionary_rows=5, converged=(False,) * 5)      # 02's family did not converge
    assert verdict.dictionary(tmp_path)[1] == verdict.BUDGET


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


def paired_csv(folder: Path, notebook: str, rows, backbone="efficientnetlite0"):
    """A planted <notebook>/paired.csv: (comparison, low, high) rows with ImageNet weights and AUC-PR
    as the metric, plus a random-init row of each that must be ignored (its interval far from 0)."""
    (folder / notebook).mkdir(parents=True, exist_ok=True)
    out = []
    for comparison, lo, hi in rows:
        for weights, (l, h) in (("imagenet", (lo, hi)), ("random init", (50.0, 60.0))):
            out.append({"backbone": backbone, "weights": weights, "label": f"{backbone} ({weights})",
                        "comparison": comparison, "a": "a", "b": "b", "metric": "AUC-PR", "difference": (l + h) / 2,
                        "low": l, "high": h, "queries": 91, "block": 10, "blocks": 10, "resolved": l > 0 or h < 0,
                        "result": "x"})
            out.append({**out[-1], "metric": "R@1", "low": 40.0, "high": 45.0})       # not the metric judged
    pd.DataFrame(out).to_csv(folder / notebook / "paired.csv", index=False)


def postprocessing_csv(folder: Path):
    """08's postprocessing.csv for one ImageNet network: AP on the evaluation part per variant."""
    (folder / "08_descriptor_postprocessing").mkdir(parents=True, exist_ok=True)
    rows = [("raw", "none", 84.0), ("PCA-whitened, paper dim", "none", 33.72), ("PCA-whitened, tuned dim", "none", 80.0),
            ("ZCA, tuned dim", "none", 70.0), ("ZCA, tuned dim", "median (tuned)", 71.0)]
    pd.DataFrame([{"backbone": "efficientnetlite0", "weights": "imagenet", "label": "EfficientNet-Lite0 (imagenet)",
                   "variant": v, "median_filter": m, "AP_eval_%": ap} for v, m, ap in rows]
                 ).to_csv(folder / "08_descriptor_postprocessing" / "postprocessing.csv", index=False)


def test_the_postprocessing_orders_are_judged_on_the_paired_interval(tmp_path):
    """Zhang 2017 and the ZCA median filter from 08's paired.csv: a resolved order against the paper
    (whitened below raw at both dimensions) does not hold, a tie is called a tie, and the cell gives
    the difference, its interval and the queries; without paired.csv the old wording stands."""
    postprocessing_csv(tmp_path)
    assert verdict.zhang_whitening(tmp_path)[1] == verdict.UNRESOLVED + " (one split, no spread)"
    paired_csv(tmp_path, "08_descriptor_postprocessing", [("PCA-whitened, paper dim minus raw", -55.1, -45.3),
                                                          ("PCA-whitened, tuned dim minus raw", -6.0, -1.5),
                                                          ("ZCA + median filter (tuned) minus ZCA", 0.0, 0.0)])
    text, word = verdict.zhang_whitening(tmp_path)
    assert word == verdict.FAILS and "AUC-PR -50.20 [-55.10, -45.30] points over 91 queries" in text
    text, word = verdict.zca_median(tmp_path)
    assert word == f"{verdict.UNRESOLVED} (tie)" and "[+0.00, +0.00] points over 91 queries" in text
    paired_csv(tmp_path, "08_descriptor_postprocessing", [("PCA-whitened, paper dim minus raw", 1.0, 9.0),
                                                          ("PCA-whitened, tuned dim minus raw", -6.0, -1.5)])
    assert verdict.zhang_whitening(tmp_path)[1] == f"{verdict.UNRESOLVED} (the two dimensions disagree)"
    paired_csv(tmp_path, "08_descriptor_postprocessing", [("PCA-whitened, paper dim minus raw", 1.0, 9.0),
                                                          ("PCA-whitened, tuned dim minus raw", 0.5, 3.0)])
    assert verdict.zhang_whitening(tmp_path)[1] == verdict.HOLDS
    assert verdict.zca_median(tmp_path)[1] == verdict.UNRESOLVED + " (one split, no spread)"   # no such row


def test_qi_depth_is_judged_on_the_paired_interval(tmp_path):
    (tmp_path / "09_rgbd_features").mkdir()
    pd.DataFrame({"backbone": ["efficientnetlite0"], "weights": ["imagenet"], "AP_RGB_pct": [50.0],
                  "AP_RGB-D_pct": [55.0]}).to_csv(tmp_path / "09_rgbd_features" / "rgbd.csv", index=False)
    paired_csv(tmp_path, "09_rgbd_features", [("RGB-D minus RGB", 1.74, 10.86)])
    text, word = verdict.qi_depth(tmp_path)
    assert word == verdict.HOLDS and "RGB-D minus RGB: AUC-PR +6.30 [+1.74, +10.86] points over 91 queries" in text
    paired_csv(tmp_path, "09_rgbd_features", [("RGB-D minus RGB", -9.0, -0.5)])
    assert verdict.qi_depth(tmp_path)[1] == verdict.FAILS
    paired_csv(tmp_path, "09_rgbd_features", [("RGB-D minus RGB", 0.0, 0.0)])
    assert verdict.qi_depth(tmp_path)[1] == f"{verdict.UNRESOLVED} (tie)"
    paired_csv(tmp_path, "09_rgbd_features", [("RGB-D minus RGB", 1.0, 2.0)], backbone="ghostnet")
    assert verdict.qi_depth(tmp_path)[1] == verdict.UNRESOLVED + " (one AP each, no spread)"   # not its network


def dictionary_seeds(folder: Path, precision, converged=(True,) * 5):
    """05's seeds.csv and seeds_summary.csv (as dictionary_threshold.seed_summary writes them) for the
    paper's variant with these per-seed closure precisions (%), and a loop-aware variant that passes."""
    from greenloop.experiments import dictionary_threshold as dt
    out = folder / "05_dictionary_threshold"
    out.mkdir(parents=True, exist_ok=True)
    (out / "manifest.json").write_text('{"parameters": {"stop_patience": 10, "stop_cap": 200}}')
    (out / "summary.json").write_text('{"derived": {"tau": 70}}')
    rows = [{"seed": k, "variant": v, "epochs": 20 + k, "final_train_acc_%": 99.0, "stopped_early": True,
             "converged": c, "precision_%": p if v == dt.VARIANTS[0] else 99.0, "event_precision_%": p,
             "recall_%": 40.0 + k} for v in dt.VARIANTS for k, (p, c) in enumerate(zip(precision, converged))]
    per_seed = pd.DataFrame(rows)
    per_seed.to_csv(out / "seeds.csv", index=False)
    dt.seed_summary(per_seed).to_csv(out / "seeds_summary.csv", index=False)


def test_a_dictionary_whose_best_seed_alone_passes_does_not_hold(tmp_path):
    """5 seeds, all converged, only the best reaching 90 % precision: the median (80) is judged, the
    spread is in the cell, and the seeds are counted by 05's own table (early stopping, epochs taken)."""
    dictionary_seeds(tmp_path, [60.0, 70.0, 80.0, 85.0, 95.0])
    text, word = verdict.dictionary(tmp_path)
    assert word == verdict.FAILS
    assert "tau = 70" in text and "median of the converged seeds 80 %, all seeds [60, 95] %" in text
    assert "5 of 5 seeds converged (trained until the training accuracy stopped rising, at most 200 epochs, " \
           "20-24 epochs taken)" in text and "recall median 42 % [40, 44]" in text
    dictionary_seeds(tmp_path, [60.0, 70.0, 92.0, 95.0, 99.0])
    assert verdict.dictionary(tmp_path)[1] == verdict.HOLDS
    dictionary_seeds(tmp_path, [95.0, 96.0, 97.0, 60.0, 70.0], converged=(False, False, False, True, True))
    text, word = verdict.dictionary(tmp_path)
    assert word == verdict.BUDGET and "2 of 5 seeds converged" in text
    dictionary_seeds(tmp_path, [float("nan")] * 5)                         # no seed flags a frame
    assert verdict.dictionary(tmp_path)[1] == verdict.FAILS


def siamese_tables(folder: Path, converged_per_arm: int, seeds=5, cap=60):
    """10's supervisions.csv and supervisions_per_seed.csv (multi-task's seed range above the others')
    with ``converged_per_arm`` of each arm's ``seeds`` networks converged by the per-seed column."""
    out = folder / "10_siamese_rgbd"
    out.mkdir(parents=True, exist_ok=True)
    arms = {"softmax": (40, 50), "contrastive": (30, 45), "multitask": (60, 70)}
    per_seed = pd.DataFrame([{"descriptor": f"scnn {x}, RGB", "seed": k, "supervision": x, "fusion": "none",
                              "epochs": 12 + 10 * k if k < converged_per_arm else cap, "epoch_cap": cap,
                              "converged": k < converged_per_arm, "AP_%": lo + (hi - lo) * k / (seeds - 1)}
                             for x, (lo, hi) in arms.items() for k in range(seeds)])
    per_seed.to_csv(out / "supervisions_per_seed.csv", index=False)
    pd.DataFrame([{"descriptor": f"scnn {x}, RGB", "supervision": x, "seeds": seeds,
                   "converged_seeds": converged_per_arm, "AP_min": lo, "AP_max": hi,
                   "epochs_min": 12, "epochs_max": cap} for x, (lo, hi) in arms.items()]
                 ).to_csv(out / "supervisions.csv", index=False)


def test_siamese_networks_are_counted_by_their_converged_column_with_the_epochs_taken(tmp_path):
    """3 of 5 networks per arm converged (9 of 15): not budget-limited, the seed ranges decide; 2 of 5
    (6 of 15): budget-limited. The cell says how many converged and the epochs they took."""
    siamese_tables(tmp_path, 3)
    text, word = verdict.xu_supervision(tmp_path)
    assert word == verdict.HOLDS and text.endswith("9 of 15 networks converged, 12-60 epochs taken (cap 60)")
    siamese_tables(tmp_path, 2)
    text, word = verdict.xu_supervision(tmp_path)
    assert word == verdict.BUDGET and "6 of 15 networks converged" in text
