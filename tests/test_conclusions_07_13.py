"""The generated conclusions of notebooks 07-13 (``<module>.conclusion(out_dir)``) on planted tables:
each order word appears only where the planted spreads separate, "not resolved" where they overlap,
and "not a ranking" where a value has no spread; the dataset is named and the verdicts come first."""
import json

import pandas as pd
import pytest

from greenloop.experiments import (descriptor_postprocessing as dp, feature_baselines as fb, leaderboard as lbx,
                                   lsh_matching, revisit_protocol, rgbd_features, siamese_rgbd)
from greenloop.study import verdict, wording

ORDER_WORDS = ("best", "ahead", "higher", "better")


def _folder(tmp_path, stem, tables, parameters=None, summary=None):
    """A results folder of the Nordland dataset holding notebook ``stem``'s planted tables ({name: rows})."""
    out = tmp_path / "results" / stem
    out.mkdir(parents=True)
    for name, rows in tables.items():
        pd.DataFrame(rows).to_csv(out / f"{name}.csv", index=False)
    (out / "manifest.json").write_text(json.dumps({"dataset": "data/nordland", "parameters": parameters or {}}))
    if summary is not None:
        (out / "summary.json").write_text(json.dumps(summary))
    return out


def _no_order_word(text):
    assert not any(w in text.lower() for w in ORDER_WORDS), text


@pytest.mark.parametrize("arms, want", [
    (((5, 60, 70), (5, 10, 50)), "a lies above b (the spreads separate)"),
    (((5, 10, 50), (5, 60, 70)), "a lies below b (the spreads separate)"),
    (((3, 60, 70), (3, 10, 50)), "a lies above b in every one of the 3 seeds, but fewer than 5 per arm: not resolved"),
    (((5, 40, 70), (5, 10, 50)), "a and b: not resolved (the spreads overlap)")])
def test_an_order_is_said_only_where_the_spreads_separate(arms, want):
    assert wording.pair_order("a", arms[0], "b", arms[1]) == want


def _table2(tmp_path, tp, fp):
    return _folder(tmp_path, "07_feature_baselines", {
        "table2": {"backbone": ["ghostnet", "mobilenetv2", "mobilenetv2:random", "sift_bovw", "pixels"],
                   "weights": ["random init", "imagenet", "random init", "none", "none"],
                   "label": ["ghostnet (random init)", "mobilenetv2 (imagenet)", "mobilenetv2 (random init)",
                             "sift_bovw (none)", "pixels (none)"],
                   "AP_%": [12.0, 80.0, 10.0, 50.0, 40.0]},
        "layers": {"backbone": ["mobilenetv2"] * 2, "depth": ["last", "mid"], "pooling": ["avg", "grid2"],
                   "chosen": [False, True], "AUC-PR_eval_%": [90.0, 95.0]},
        "dictionary_operating_points": {"tau": [60, 70], "precision": [0.5, tp / max(1, tp + fp)], "recall": [0.5, tp / 10],
                                        "tp": [5, tp], "fp": [5, fp], "fn": [5, 10 - tp]}},
        parameters={"frames_per_spot": 60}, summary={"chance_ap": 0.01})


def test_07_gives_every_ap_without_an_order_and_the_dictionary_at_l_plus_10(tmp_path):
    text = fb.conclusion(_table2(tmp_path, 3, 1))
    assert text.startswith("### Conclusion on Nordland") and "**not testable here**" in text
    assert "mobilenetv2 (imagenet) 80 %" in text and "the 2 random-init rows [10, 12] %" in text and "not a ranking" in text
    assert "mobilenetv2 mid-grid2 95 % (last-avg 90 %)" in text
    assert "τ = 70 declares 4 pairs, 3 of them loops: precision 0.75, recall 0.3 of 10 loop pairs" in text
    _no_order_word(text)
    assert "τ = 70 declares no pair (recall 0 of 10 loop pairs)" in fb.conclusion(_table2(tmp_path / "b", 0, 0))


def _postprocessing(tmp_path, whiten_spread, split=True):
    variants = [("raw", "none", 50.0), ("L2", "none", 52.0), ("PCA-whitened, paper dim", "none", 30.0),
                ("PCA-whitened, tuned dim", "none", 60.0), ("ZCA, tuned dim", "none", 60.0),
                ("ZCA, tuned dim", "median (tuned)", 61.0)]
    ap = "AP_eval_%" if split else "AP_all_%"
    rows = {"backbone": "mobilenetv2", "weights": "imagenet", "label": "mobilenetv2 (imagenet)",
            "variant": [v for v, _, _ in variants], "median_filter": [m for _, m, _ in variants],
            "size": 1, ap: [a for *_, a in variants]}
    spread = ({"label": "mobilenetv2 (imagenet)", "knob": ["PCA-whitening dim", "median size, L2"],
               "min": [55.0, 50.0], "max": [55.0 + whiten_spread, 55.0], "spread": [whiten_spread, 5.0]}
              if split else {"status": ["not available"]})
    return _folder(tmp_path, "08_descriptor_postprocessing", {"postprocessing": rows, "split_spread": spread})


def test_08_sets_each_gain_against_the_spread_of_its_pick_over_the_two_splits(tmp_path):
    text = dp.conclusion(_postprocessing(tmp_path, 4.0))
    assert "raw 50, L2 52, PCA-whitened at the paper's dim 30, at the tuned dim 60" in text
    assert "whitening at the tuned dim over raw +10.00 points, beyond the 4-point spread" in text
    assert "two splits are too few to call an order: not resolved" in text
    assert "the median filter on ZCA +1.00 points, within the 5-point spread" in text
    assert "+10.00 points, within the 12-point spread" in dp.conclusion(_postprocessing(tmp_path / "b", 12.0))
    _no_order_word(text)
    nosplit = dp.conclusion(_postprocessing(tmp_path / "c", 4.0, split=False))
    assert "every query (no honest split" in nosplit and "No honest tuning/evaluation split here" in nosplit
    assert "**not testable here**" in nosplit                    # the verdict has no evaluation part to read


def test_09_gives_rgb_and_rgbd_ap_or_says_there_is_no_depth(tmp_path):
    out = _folder(tmp_path, "09_rgbd_features", {"rgbd": {
        "backbone": ["efficientnetlite0"], "weights": ["imagenet"], "label": ["efficientnetlite0 (imagenet)"],
        "AP_RGB_%": [67.0], "AP_depth_%": [20.0], "AP_RGB-D_%": [70.0]}})
    text = rgbd_features.conclusion(out)
    assert "efficientnetlite0 (imagenet) 67 -> 70 (depth alone 20)" in text and "not a ranking" in text
    assert "**not resolved (one AP each, no spread)**" in text
    _no_order_word(text)
    skipped = _folder(tmp_path / "b", "09_rgbd_features", {"rgbd": {"backbone": ["vgg19"], "weights": ["random init"], "status": ["skipped"]}})
    assert "Nordland has no depth/ folder" in rgbd_features.conclusion(skipped)


def _siamese(tmp_path, conv1, p83):
    sup = {"descriptor": ["scnn softmax, RGB", "scnn contrastive, RGB", "scnn multitask, RGB", "scnn untrained, RGB",
                          "pixels (32x32 gray)"],
           "supervision": ["softmax", "contrastive", "multitask", "none", "none"], "seeds": [5, 5, 5, 5, 1],
           "AP_mean": [45.0, 25.0, 65.0, 12.0, 25.0], "AP_min": [40.0, 20.0, 60.0, 10.0, 25.0],
           "AP_max": [50.0, 30.0, 70.0, 15.0, 25.0]}
    fus = {"descriptor": ["RGB only (multitask)", "scnn early fusion", "scnn mid-level fusion at conv1",
                          "scnn mid-level fusion at conv2", "scnn late fusion"],
           "fusion": ["RGB only", "early", "mid", "mid", "late"], "layer": ["", "", "conv1", "conv2", ""],
           "seeds": 5, "AP_min": [60.0, 40.0, conv1[0], 45.0, 75.0], "AP_max": [70.0, 50.0, conv1[1], 55.0, 80.0]}
    cmp = {"quantity": [siamese_rgbd.LEVELLING, "precision at 83 % recall, multi-task", "precision at 82 % recall, late fusion"],
           "this run": ["+1.0 then +0.1 points over 9 networks", p83, "0.500 [0.400, 0.600]"]}
    tim = {"descriptor": ["scnn multitask, RGB", "sift_bovw"], "s_per_image_one_at_a_time": [0.001, 0.02]}
    return _folder(tmp_path, "10_siamese_rgbd", {"supervisions": sup, "fusions": fus, "paper_vs_run": cmp, "timing": tim},
                   summary={"chance_ap": 0.01})


def test_10_reads_training_layers_and_the_papers_operating_points_from_the_tables(tmp_path):
    text = siamese_rgbd.conclusion(_siamese(tmp_path, (30.0, 40.0), "0.950 [0.910, 0.970]"))
    assert "*multi-task supervision ranks first*" in text and "**holds**" in text          # 5 seeds, separated
    assert "softmax [40, 50] (every seed above both)" in text and "contrastive [20, 30] (not separated from them)" in text
    assert "none of this is an order" not in text                                         # 5 seeds per arm
    assert "0.950 [0.910, 0.970], reached by the best seed (paper: > 0.90" in text
    assert "0.500 [0.400, 0.600], reached by no seed (paper: 0.92" in text
    assert "conv2 first (Table 2): holds" in text and "a 20x ratio; one timing each" in text and "not a ranking" in text
    overlap = siamese_rgbd.conclusion(_siamese(tmp_path / "b", (50.0, 60.0), "0.5 [0.4, 0.6]"))
    assert "conv2 first (Table 2): not resolved (seed ranges overlap)" in overlap


def _lsh(tmp_path, qdp_ms):
    variants = ["brute force", "SWP-RHLSH", "QDP-RHLSH"]
    t6 = {"backbone": "mobilenetv1", "weights": "imagenet", "label": "mobilenetv1 (imagenet)", "variant": variants,
          "ms_per_query": [0.02, 0.1, qdp_ms], "ms_sd": [0.001, 0.01, 0.002], "AP_pairs_%": [80.0, 78.0, 79.5],
          "AP_pairs_sd": [0.0, 1.0, 1.0], "R@1_%": [90.0, 89.0, 90.0], "R_a_%": [0.0, -2.5, -0.6], "scanned_%": [100, 60, 70]}
    seeds = {"backbone": "mobilenetv1", "variant": [v for v in variants for _ in range(3)], "seed": [0, 1, 2] * 3}
    return _folder(tmp_path, "11_lsh_matching", {"table6": t6, "per_seed": seeds,
                                                 "paper_vs_run": {"quantity": ["hash length (bits)"], "this run": [16]}},
                   summary={"main": "mobilenetv1"})


def test_11_orders_times_and_aps_only_where_mean_sd_ranges_separate(tmp_path):
    text = lsh_matching.conclusion(_lsh(tmp_path, 0.021))
    assert "(mean ± sd over 3 hyperplane seeds)" in text
    assert "SWP-RHLSH 0.1 ± 0.01 ms is slower than brute force 0.02 ± 0.001 ms (the spreads separate)" in text
    assert "QDP-RHLSH 0.021 ± 0.002 ms and brute force 0.02 ± 0.001 ms: not resolved (the spreads overlap)" in text
    assert "SWP-RHLSH 78 ± 1 % lies below brute force 80 ± 0 %" in text
    assert "QDP-RHLSH 79.5 ± 1 % and brute force 80 ± 0 %: not resolved" in text
    assert "QDP-RHLSH 0.03 ± 0.002 ms is slower than" in lsh_matching.conclusion(_lsh(tmp_path / "b", 0.03))


def _revisit(tmp_path, seeds, chosen_precision):
    summary = {"split": ["random", "random", "blocked", "blocked"], "seeds": seeds,
               "scored_on": ["in_traversal_test_acc_%", "revisit_acc_%"] * 2,
               "mean": [97.0, 60.0, 80.0, 82.0], "min": [96.0, 55.0, 75.0, 78.0], "max": [99.0, 65.0, 85.0, 86.0]}
    d = {"seed": [k for k in range(seeds) for _ in range(2)], "tau_rule": ["chosen on the tuning part", "paper: L + Δ"] * seeds,
         "tau": [65, 70] * seeds, "precision": [chosen_precision, 0.55] * seeds, "recall": [0.5, 0.5] * seeds}
    return _folder(tmp_path, "12_revisit_protocol", {"summary_table": summary, "dictionary_tuned": d},
                   summary={"split": {"honest": True}})


def test_12_compares_the_same_models_in_the_traversal_and_on_the_revisit(tmp_path):
    text = revisit_protocol.conclusion(_revisit(tmp_path, 5, 0.85))
    assert text.startswith("### Conclusion on Nordland\n\n")                      # no claim of the verdict's here
    assert "in-traversal test accuracy 97 [96, 99] % lies above the revisit accuracy 60 [55, 65] % (the spreads separate)" in text
    assert "the paper's 98 % is reached by the best seed" in text
    assert "80 [75, 85] % and the revisit accuracy 82 [78, 86] %: not resolved (the spreads overlap)" in text
    assert "precision at the chosen τ 0.85 lies above at τ = 70 0.55 (the spreads separate)" in text
    assert "recall at the chosen τ 0.5 and at τ = 70 0.5: not resolved" in text
    assert "budget" not in text.lower()                                          # summary.json carries no label
    out = _revisit(tmp_path / "c", 5, 0.85)
    info = json.loads((out / "summary.json").read_text())
    (out / "summary.json").write_text(json.dumps({**info, "budget": "budget-limited: 3 of 10 seeds converged"}))
    assert revisit_protocol.conclusion(out).startswith(
        "### Conclusion on Nordland\n\n**Budget-limited: 3 of 10 seeds converged**: most runs ended on their epoch budget")
    few = revisit_protocol.conclusion(_revisit(tmp_path / "b", 3, 0.55))
    assert "in every one of the 3 seeds, but fewer than 5 per arm: not resolved" in few
    assert "precision at the chosen τ 0.55 and at τ = 70 0.55: not resolved" in few


def _board(tmp_path, comparisons=True):
    methods = ["greenloop-seq", "greenloop-seq-grad", "SeqSLAM (published)", "main paper: CNN + dictionary"]
    board = {"method": methods, "mode": "loop closure", "queries": 100, "revisit_queries": 40,
             "R@1_%": [90.0, 70.0, 40.0, None], "R@1_lo_%": [80.0, 50.0, 30.0, None], "R@1_hi_%": [95.0, 85.0, 50.0, None],
             "threshold": [1.0, 3.0, 0.5, 70], "closures_declared": [None, None, None, 10], "closures_false": [None, None, None, 1],
             "scored_on": "evaluation queries"}
    comp = {"protocol": "leaderboard", "a": ["greenloop-seq", "greenloop-seq", "greenloop-seq-grad", "greenloop-seq-grad"],
            "b": ["SeqSLAM (published)", "greenloop-seq-grad", "SeqSLAM (published)", "greenloop-seq"], "metric": "R@1",
            "difference": [50.0, 20.0, 30.0, -20.0], "lo": [30.0, -5.0, 5.0, -40.0], "hi": [60.0, 40.0, 50.0, 5.0],
            "resolved": [True, False, True, False]}
    targets = {"protocol": "leaderboard", "configuration": "greenloop-seq-grad",
               "target": ["frames/s (slowest repeat)", "closure precision at the threshold (%)", "R@1 above X: the low end"],
               "measured": [1000.0, 80.0, None], "required": [">= 920", ">= 90", "> 0"], "met": [True, False, None]}
    tables = {"leaderboard": board, "targets": targets, **({"comparisons": comp} if comparisons else {})}
    return _folder(tmp_path, "13_leaderboard", tables)


def test_13_gives_the_dictionary_verdict_the_standing_and_the_targets(tmp_path):
    text = lbx.conclusion(_board(tmp_path))
    assert "*tau = L + Delta declares loop closures*" in text and "9 of 10 closures right" in text \
        and "**not resolved (convergence of its CNN not recorded)**" in text     # one seed, no 02 run beside it
    assert "(100 evaluation queries, 40 with a partner; loop closure)" in text
    assert "greenloop-seq R@1 90 % [80, 95], paired R@1 resolved above 1 and below 0 of the 2 other rows" in text
    assert "greenloop-seq-grad R@1 70 % [50, 85], paired R@1 resolved above 1 and below 0 of the 2 other rows, " \
           "not resolved against 1" in text
    assert ("meets 1 of its 2 targets judged on the leaderboard (not met: closure precision at the threshold (%)), "
            "1 not measured there") in text
    _no_order_word(text)
    assert "no paired comparisons in this folder: no order is called" in lbx.conclusion(_board(tmp_path / "b", False))
    assert "false closures" not in text                   # no false_closures.csv: nothing said


def test_13_says_where_the_named_defaults_false_closures_lie(tmp_path):
    out = _board(tmp_path)
    run = {"protocol": "leaderboard", "configuration": "greenloop-seq-grad", "first_query": [2064, 3000],
           "last_query": [2096, 3000], "first_match": [1020, 40], "last_match": [1052, 40], "closures": [9, 1],
           "with_partner": [4, 0], "offset_frames": [258.0, None], "max_score": [5.7, 3.1],
           "distance_m": [1.96, 7.0], "angle_deg": [0.4, 90.0]}
    pd.DataFrame(run).to_csv(out / "false_closures.csv", index=False)
    assert ("Its 10 false closures at the fixed threshold lie in 2 run(s) of consecutive queries; the longest, queries "
            "2064-2096 matched to frames 1020-1052 (9 closures), at 1.96 m from the query's camera, optical axes 0 "
            "degrees apart (medians)") in lbx.conclusion(out)
    pd.DataFrame(run).drop(columns=["distance_m", "angle_deg"]).to_csv(out / "false_closures.csv", index=False)
    assert "at 258 frames from the query's nearest partner (median)" in lbx.conclusion(out)
    pd.DataFrame(run).iloc[:0].to_csv(out / "false_closures.csv", index=False)
    assert "Every closure greenloop-seq-grad declares on the leaderboard's evaluation queries is right." in lbx.conclusion(out)


def test_every_conclusion_names_the_verdicts_of_its_notebook(tmp_path):
    """heading: the dataset's name, then study.verdict's bullets for the notebook's claims (none for 12)."""
    out = _revisit(tmp_path, 5, 0.85)
    assert wording.heading(out.parent, "12_revisit_protocol") == "### Conclusion on Nordland"
    head = wording.heading(out.parent, "10_siamese_rgbd")
    assert head.count("\n* Xu 2022") == sum(c.notebook == "10_siamese_rgbd" for c in verdict.CLAIMS)


def _paired_rows(comparison, a, b, low, high, label="mobilenetv2 (imagenet)"):
    """paired.csv rows (leaderboard.rows.paired_table's columns) of one comparison, both metrics alike."""
    from greenloop.experiments.leaderboard import rows as lb
    resolved = low > 0 or high < 0
    result = lb.TIE if not resolved else f"{a} above {b}" if low > 0 else f"{b} above {a}"
    return [{"backbone": label.split(" ")[0], "weights": "imagenet", "label": label, "comparison": comparison, "a": a,
             "b": b, "metric": m, "difference": (low + high) / 2, "low": low, "high": high, "queries": 200, "block": 10,
             "blocks": 20, "resolved": resolved, "result": result} for m in ("R@1", "AUC-PR")]


def test_08_says_which_paired_comparisons_resolve_and_which_tie(tmp_path):
    out = _postprocessing(tmp_path, 4.0)
    rows = (_paired_rows("PCA-whitened, paper dim minus raw", "PCA-whitened, paper dim", "raw", -30.0, -10.0)
            + _paired_rows("ZCA + median filter (tuned) minus ZCA", dp.MEDIAN_ARM, "ZCA, tuned dim", -2.0, 3.0))
    pd.DataFrame(rows).to_csv(out / "paired.csv", index=False)
    text = dp.conclusion(out)
    assert "PCA-whitened, paper dim minus raw: AUC-PR -20.00 points [-30.00, -10.00]" in text
    assert "over 200 queries in 20 blocks of 10), resolved: raw above PCA-whitened, paper dim" in text
    assert "ZCA + median filter (tuned) minus ZCA: AUC-PR +0.50 points [-2.00, +3.00]" in text and "not resolved" in text
    assert "not resolved by the two splits" in text
    _no_order_word(text)


def test_09_says_whether_depth_adds_to_rgb_paired(tmp_path):
    out = _folder(tmp_path, "09_rgbd_features", {"rgbd": {
        "backbone": ["efficientnetlite0"], "weights": ["imagenet"], "label": ["efficientnetlite0 (imagenet)"],
        "AP_RGB_%": [67.0], "AP_depth_%": [20.0], "AP_RGB-D_%": [70.0]}})
    pd.DataFrame(_paired_rows("RGB-D minus RGB", "RGB-D", "RGB", 1.0, 5.0, "efficientnetlite0 (imagenet)")).to_csv(
        out / "paired.csv", index=False)
    text = rgbd_features.conclusion(out)
    assert "efficientnetlite0 (imagenet): RGB-D minus RGB: AUC-PR +3.00 points [+1.00, +5.00]" in text
    assert "resolved: RGB-D above RGB" in text
    _no_order_word(text)
