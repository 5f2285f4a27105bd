"""The descriptor experiments (notebooks 07, 08, 09, 11) on tiny inputs made here: each table
against the stage functions it composes, or against values worked out by hand."""
from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd
import pytest

from greenloop import evaluate, similarity
from greenloop.datasets import sequence
from greenloop.experiments import descriptor_postprocessing as dp, feature_baselines as fb, lsh_matching, rgbd_features
from greenloop.methods.dictionary import dictionary
from greenloop.methods.lsh import lsh
from greenloop.speed import timing
from test_evaluate import EXCL, N, hand_example


@dataclass
class Info:                                   # the fields of features.ExtractInfo the tables read
    backbone: str
    weights: str = "random init"
    dim: int = 6
    input_size: tuple | None = (64, 64)
    seconds_per_image: float = 0.01

    @property
    def label(self):
        return f"{self.backbone} ({self.weights})"


def revisiting(n_place=20, dim=12, seed=0, noise=0.3):
    """2 n_place frames: the second half revisits the first (GT[i, i + n_place]), noisy descriptors."""
    rng = np.random.default_rng(seed)
    base = rng.standard_normal((n_place, dim))
    X = np.concatenate([base, base]) + noise * rng.standard_normal((2 * n_place, dim))
    GT = np.zeros((2 * n_place, 2 * n_place), bool)
    i = np.arange(n_place)
    GT[i, i + n_place] = GT[i + n_place, i] = True
    return X, GT


# ---------------------------------------------------------------------------------- 11: LSH
def test_match_runs_and_table6_are_the_stage_runs_averaged():
    X, GT = revisiting()
    feats, infos = {"a": X, "b": np.abs(X)}, {"a": Info("a"), "b": Info("b")}
    runs = lsh_matching.match_runs(feats, infos, GT, 5, [0, 1], n_bits=6, radius=1, centre=False)
    ps = runs.per_seed
    # sklearn runs with the first seed only: 4 variants x 2 seeds - 1, per backbone
    assert len(ps) == 2 * 7 and (ps.variant == "NearestNeighbors (sklearn)").sum() == 2
    swp = lsh.incremental_match(X, "swp", exclude=5, n_bits=6, seed=1, radius=1, keep_candidates=True)
    brute = lsh.incremental_match(X, "brute", exclude=5, seed=1, keep_candidates=True)
    want = lsh_matching.run_scores(swp, similarity.cosine_matrix(X), brute, GT, 5)
    got = ps[(ps.backbone == "a") & (ps.variant == "SWP-RHLSH") & (ps.seed == 1)].iloc[0]
    for k in ("R@1_%", "AUC-PR_%", "AP_pairs_%", "NN_agree_%", "scanned_%", "N1_at_end"):
        assert got[k] == pytest.approx(want[k])
    assert runs.ap_full["a"] == pytest.approx(100 * evaluate.average_precision(similarity.cosine_matrix(X), GT, 5))
    table = lsh_matching.table6(runs, n_bits=6, radius=1)
    assert list(table.columns[:5]) == ["backbone", "weights", "label", "variant", "probing"]
    a = table[table.backbone == "a"].set_index("variant")
    sw = ps[(ps.backbone == "a") & (ps.variant == "SWP-RHLSH")]
    assert a.loc["SWP-RHLSH", "AP_pairs_%"] == pytest.approx(sw["AP_pairs_%"].mean())
    assert a.loc["brute force", "R_a_%"] == 0 and a.loc["SWP-RHLSH", "probing"] == "6 bits, m = 1"
    with pytest.raises(ValueError, match="seeds is empty"):
        lsh_matching.match_runs(feats, infos, GT, 5, [])


def test_figure7_curves_and_overlap():
    X, GT = revisiting()
    runs = lsh_matching.match_runs({"a": X}, {"a": Info("a")}, GT, 5, [0], n_bits=6, radius=1, centre=True)
    curves = lsh_matching.figure7_curves(runs, GT, 5, 0)
    assert list(curves) == [("a", v) for v in lsh_matching.FIGURE7_STYLES]   # sklearn is not drawn
    p, r = lsh_matching.scanned_pr_curve(runs.S["a"], runs.runs["a", "QDP-RHLSH", 0], GT, 5)
    assert np.array_equal(curves["a", "QDP-RHLSH"][0], p) and np.array_equal(curves["a", "QDP-RHLSH"][1], r)
    ov = lsh_matching.figure7_overlap(curves, {"a": Info("a")}, 0, np.linspace(0, 1, 11), 0.02).set_index("variant")
    assert ov.loc["brute force", "overlap_recall"] == 1.0          # brute force stays with itself
    assert ov.loc["QDP-RHLSH", "max_recall"] == pytest.approx(r.max())


# ------------------------------------------------------------------ 08: post-processing
def test_honest_split_is_split_mask_or_the_note():
    X, GT = revisiting()                               # revisit frames 20..39
    tune, evq, note = evaluate.honest_split(40, 0.5, GT, 3)
    t0, e0 = evaluate.split_mask(40, 0.5, gt=GT, gap=3)
    assert note is None and np.array_equal(tune, t0) and np.array_equal(evq, e0)
    tune, evq, note = evaluate.honest_split(40, 0.5, GT, 25, dropped="the tuned rows", kept="nothing else")
    assert tune is None and evq is None
    assert note.startswith("**No honest tuning/evaluation split:**") and note.endswith("nothing else.")


def test_tune_then_score_picks_on_the_tuning_queries_only():
    S, GT = hand_example()
    early, late = np.arange(N) <= 4, np.arange(N) >= 5
    bad = np.where(GT, 0.0, 1.0)                 # ranks every non-loop above every loop
    # the candidate that is perfect on the tuning queries wins, whatever it does elsewhere
    good_early = S.copy()
    good_early[:, late] = bad[:, late]
    good_early[late, :] = bad[late, :]
    r = dp.tune_then_score({"a": good_early, "b": bad}, GT, EXCL, early, late)
    assert r["value"] == "a" and r["AP_tune"] == pytest.approx(evaluate.average_precision(good_early, GT, EXCL, early))
    assert r["AP_eval"] == pytest.approx(evaluate.average_precision(good_early, GT, EXCL, late))
    assert r["R@100P_eval"] == evaluate.recall_at_100_precision(good_early, GT, EXCL, late)
    assert r["AP_tune_all"] == {"a": r["AP_tune"], "b": evaluate.average_precision(bad, GT, EXCL, early)}
    with pytest.raises(ValueError, match="empty"):
        dp.tune_then_score({}, GT, EXCL, early, late)


def test_whitened_variants_pick_the_dimension_on_the_tuning_part():
    X, GT = revisiting()
    tune, evq = evaluate.split_mask(40, 0.5, gt=GT, gap=3)
    variants, curves = dp.whitened_variants(X, GT, 5, tune, evq, pca_dim=6, dims=(2, 4, 8))
    assert list(variants) == ["raw", "L2", "PCA-whitened, paper dim", "PCA-whitened, tuned dim", "ZCA, tuned dim"]
    assert np.array_equal(variants["raw"][0], similarity.distance_similarity(X, normalise=False))
    assert variants["PCA-whitened, paper dim"][1] == "dim 6 (paper 6)"
    assert list(curves) == ["pca dim", "zca dim"] and list(curves["pca dim"]) == [2, 4, 8]
    cands = similarity.whitened_similarities(similarity.l2_normalise(X), (2, 4, 8), "pca", 1e-5, fit=tune)
    pick = dp.tune_then_score(cands, GT, 5, tune, evq)["value"]
    assert variants["PCA-whitened, tuned dim"][1] == f"dim {pick} (picked on tuning part)"
    assert np.array_equal(variants["PCA-whitened, tuned dim"][0], cands[pick])
    untuned, none = dp.whitened_variants(X, GT, 5, None, None, pca_dim=6, dims=(2, 4, 8))
    assert list(untuned) == ["raw", "L2", "PCA-whitened, paper dim"] and none == {}
    assert untuned["PCA-whitened, paper dim"][1] == "dim 6 (paper 6), fitted on every frame"


def test_median_scores_rows_with_and_without_a_split():
    X, GT = revisiting()
    S = similarity.distance_similarity(X)
    tune, evq = evaluate.split_mask(40, 0.5, gt=GT, gap=3)
    rows, curve = dp.median_scores(S, GT, 5, tune, evq, sizes=(1, 3))
    assert [r["median_filter"] for r in rows] == ["none", "median (tuned)"] and list(curve) == [1, 3]
    assert rows[0]["size"] == 1 and rows[1]["size"] == max(curve, key=curve.get)
    assert rows[0]["AP_eval_%"] == 100 * evaluate.average_precision(S, GT, 5, queries=evq)
    assert rows[0]["AP_tune_%"] == 100 * curve[1]
    thr = evaluate.mpca_threshold(S, GT, 5, queries=tune)
    assert rows[0]["MPCA_threshold"] == thr
    assert rows[0]["MPCA_eval"] == evaluate.mean_per_class_accuracy(S, GT, thr, 5, queries=evq)
    (row,), none = dp.median_scores(S, GT, 5, None, None, sizes=(1, 3))
    assert none is None and np.isnan(row["AP_tune_%"]) and np.isnan(row["MPCA_eval"])
    assert row["AP_all_%"] == 100 * evaluate.average_precision(S, GT, 5)


def test_swapped_split_tunes_on_either_part():
    X, GT = revisiting()
    S_l2 = similarity.distance_similarity(X)
    tune, evq = evaluate.split_mask(40, 0.5, gt=GT, gap=3)
    rows = dp.swapped_split(X, S_l2, GT, 5, tune, evq, dims=(2, 4), sizes=(1, 3))
    assert [(r["split"][0], r["knob"]) for r in rows] == [("A", "PCA-whitening dim"), ("A", "median size, L2"),
                                                         ("B", "PCA-whitening dim"), ("B", "median size, L2")]
    r = dp.tune_then_score(similarity.median_candidates(S_l2, (1, 3)), GT, 5, evq, tune)   # B: tune late, score early
    assert rows[3]["picked"] == r["value"] and rows[3]["AP_eval_%"] == 100 * r["AP_eval"]


def test_postprocessing_rows_are_the_stage_scores_of_every_variant():
    X, GT = revisiting()
    tune, evq = evaluate.split_mask(40, 0.5, gt=GT, gap=3)
    sc = dp.postprocessing({"a": X}, {"a": Info("a")}, GT, 5, tune, evq, pca_dim=6, dims=(2, 4), sizes=(1, 3))
    variants, curves = dp.whitened_variants(X, GT, 5, tune, evq, pca_dim=6, dims=(2, 4))
    assert list(sc.variants["a"]) == list(variants)
    # two rows (unfiltered, median-tuned) per variant, in the variants' order
    assert list(sc.table.variant) == [v for v in variants for _ in range(2)]
    rows, curve = dp.median_scores(variants["ZCA, tuned dim"][0], GT, 5, tune, evq, sizes=(1, 3))
    got = sc.table[sc.table.variant == "ZCA, tuned dim"].reset_index(drop=True)
    assert got.loc[1, "AP_eval_%"] == pytest.approx(rows[1]["AP_eval_%"])
    assert got.loc[1, "MPCA_eval"] == pytest.approx(rows[1]["MPCA_eval"])
    assert got.loc[0, "whitening"] == variants["ZCA, tuned dim"][1]
    # tuning: the whitening curves first, then one median curve per variant
    assert list(dict.fromkeys(sc.tuning.knob)) == ["pca dim", "zca dim"] + [f"median size, {v}" for v in variants]
    t = sc.tuning[sc.tuning.knob == "pca dim"]
    assert t["AP_tune_%"].tolist() == pytest.approx([100 * curves["pca dim"][d] for d in (2, 4)])


def test_postprocessing_and_second_split_without_a_split():
    X, GT = revisiting()
    sc = dp.postprocessing({"a": X}, {"a": Info("a")}, GT, 5, None, None, pca_dim=6, dims=(2, 4), sizes=(1, 3))
    assert list(sc.table.variant) == ["raw", "L2", "PCA-whitened, paper dim"]
    assert sc.table["AP_all_%"].iloc[1] == pytest.approx(100 * evaluate.average_precision(sc.variants["a"]["L2"][0], GT, 5))
    assert sc.tuning.to_dict("records") == [{"status": dp.NOT_AVAILABLE}]
    swap = dp.second_split({"a": X}, {"a": Info("a")}, sc.variants, GT, 5, None, None)
    assert swap.to_dict("records") == [{"status": dp.NOT_AVAILABLE}]
    assert dp.split_spread(swap).equals(swap)


def test_second_split_and_its_spread():
    X, GT = revisiting()
    tune, evq = evaluate.split_mask(40, 0.5, gt=GT, gap=3)
    sc = dp.postprocessing({"a": X}, {"a": Info("a")}, GT, 5, tune, evq, pca_dim=6, dims=(2, 4), sizes=(1, 3))
    swap = dp.second_split({"a": X}, {"a": Info("a")}, sc.variants, GT, 5, tune, evq, dims=(2, 4), sizes=(1, 3))
    want = dp.swapped_split(X, sc.variants["a"]["L2"][0], GT, 5, tune, evq, dims=(2, 4), sizes=(1, 3))
    assert swap.drop(columns=["backbone", "label"]).to_dict("records") == want
    hand = pd.DataFrame({"label": ["x"] * 4, "knob": ["k", "k", "m", "m"], "AP_eval_%": [10.0, 12.5, 30.0, 20.0]})
    s = dp.split_spread(hand)
    assert s.to_dict("records") == [{"label": "x", "knob": "k", "min": 10.0, "max": 12.5, "spread": 2.5},
                                    {"label": "x", "knob": "m", "min": 20.0, "max": 30.0, "spread": 10.0}]


def test_paper_rows_of_08_copy_the_table():
    X, GT = revisiting()
    tune, evq = evaluate.split_mask(40, 0.5, gt=GT, gap=3)
    info = {"resnet50": Info("resnet50", weights="imagenet")}
    sc = dp.postprocessing({"resnet50": X}, info, GT, 5, tune, evq, pca_dim=6, dims=(2, 4), sizes=(1, 3))
    cmp = dp.paper_rows(sc.table, sc.variants, info, 6, 1e-5, True, {"resnet50": (0.832, 0.880)}).set_index("quantity")
    z = sc.table[(sc.table.variant == "ZCA, tuned dim") & (sc.table.median_filter == "median (tuned)")].iloc[0]
    assert cmp.loc["MPCA, ZCA + median filter, resnet50", "this run"] == f"{z.MPCA_eval:.3f} (AP {z['AP_eval_%']:.2f} %)"
    assert cmp.loc["best pretrained network with ZCA + median filter, by MPCA", "this run"].startswith("resnet50 (imagenet)")


# --------------------------------------------------------------------- 07: Table 2
def test_table2_scores_and_rates_against_sift_bovw():
    X, GT = revisiting()
    feats = {"sift_bovw": X, "cnn": X + 0.5 * np.random.default_rng(1).standard_normal(X.shape)}
    infos = {"sift_bovw": Info("sift_bovw", "none", seconds_per_image=0.02), "cnn": Info("cnn", seconds_per_image=0.01)}
    S, secs = fb.similarity_matrices(feats, repeats=2)
    assert np.array_equal(S["cnn"], similarity.cosine_matrix(feats["cnn"])) and all(s > 0 for s in secs.values())
    t = fb.table2(S, infos, secs, GT, 5).set_index("backbone")
    ap = 100 * evaluate.average_precision(S["cnn"], GT, 5)
    assert t.loc["cnn", "AP_%"] == pytest.approx(ap)
    assert t.loc["cnn", "R@1_%"] == pytest.approx(100 * evaluate.recall_at_k(S["cnn"], GT, 1, 5))
    ref = t.loc["sift_bovw", "AP_%"]
    assert t.loc["cnn", "R_a_%"] == pytest.approx(100 * (ap - ref) / ref)
    assert t.loc["cnn", "R_t_%"] == pytest.approx(50.0)               # 0.01 s against SIFT's 0.02 s
    assert t.loc["sift_bovw", "R_a_%"] == 0 and t.loc["cnn", "input"] == "64x64"
    assert fb.table2({"cnn": S["cnn"]}, infos, secs, GT, 5)["R_a_%"].isna().all()   # no reference row


def test_operating_points_table_and_the_dictionary_row_of_07():
    points = [{"tau": 12, "flagged_frames": 4, "closures": {}, "op": dict(precision=0.5, recall=0.25, tp=1, fp=1, fn=3, ignored=0)},
              {"tau": 20, "flagged_frames": 0, "closures": {}, "op": dict(precision=np.nan, recall=0.0, tp=0, fp=0, fn=4, ignored=0)}]
    ops = fb.operating_points_table(points, {"spot_cnn": Info("spot_cnn", "model:x")})
    assert list(ops.columns) == ["detector", "tau", "flagged_frames", "precision", "recall", "tp", "fp", "fn", "ignored"]
    assert ops.detector[0] == "dictionary, spot_cnn (model:x)" and ops.tp.tolist() == [1, 0]
    table = pd.DataFrame([{"backbone": b, "weights": "imagenet", "label": f"{b} (imagenet)", "input": "64x64",
                           "AP_%": ap, "extract_s_per_image": 0.01, "R_a_%": np.nan, "R_t_%": np.nan}
                          for b, ap in (("ghostnet", 40.0), ("ghostnet@mid-grid2", 45.0), ("mobilenetv2", 30.0))])
    cmp = fb.paper_rows(table, ops, {"ghostnet": (53.1, 0.036, 40.5, 29.4)}, frames_per_spot=2).set_index("quantity")
    assert cmp.loc["AP / average accuracy rate, ghostnet (%)", "this run"] == 40.0
    assert cmp.loc["R_a vs SIFT-BoVW, ghostnet (%)", "this run"] == "no sift_bovw row"
    # the papers' descriptors, ranked with the runner-up beside; the tuned layer row is left out
    assert cmp.loc["highest AP among the pretrained CNN descriptors", "this run"] == (
        "ghostnet (imagenet): 40.0 %; next: mobilenetv2 (imagenet): 30.0 %")
    assert cmp.loc["dictionary detector at τ = 12: precision / recall", "this run"] == "0.500 / 0.250"   # τ nearest L + 10


def _pose_folder(folder, n=24):
    """n random frames whose camera walks 0 .. 5.5 m along x and back: frame i and n - 1 - i share a place."""
    from conftest import write_frames
    write_frames(folder, n)
    x = np.r_[np.arange(n // 2), np.arange(n // 2)[::-1]] * 0.5
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = x
    sequence.write_trajectory(folder / "CameraTrajectory.txt", np.arange(n), poses)
    return folder


def test_ground_truth_sensitivity_is_the_ap_under_each_variant(tmp_path):
    from greenloop import groundtruth
    folder = _pose_folder(tmp_path / "seq")
    frames = np.arange(24)
    S = {"a": similarity.cosine_matrix(np.random.default_rng(0).standard_normal((24, 5)))}
    t = fb.ground_truth_sensitivity(folder, frames, S, {"a": Info("a")}, 4, 4, thresholds=(0.3, 1.2),
                                    max_distance=0.6, max_angle=30)
    GTV = groundtruth.variants(folder, frames, (0.3, 1.2), 4, 0.6, 30)
    assert t.ground_truth.tolist() == list(GTV)
    for (name, G), row in zip(GTV.items(), t.itertuples()):
        assert row.loop_pairs == len(groundtruth.loop_pairs(G))
    for name, G in GTV.items():
        ap = t.set_index("ground_truth").loc[name, "a (random init)"]
        assert ap == pytest.approx(100 * evaluate.average_precision(S["a"], G, 4)) if G.any() else np.isnan(ap)
    pairs = tmp_path / "pairs"
    from conftest import write_frames
    write_frames(pairs, 24)
    sequence.write_loop_pairs(pairs / sequence.GROUND_TRUTH_NAME, [(0, 23, 0)])
    assert fb.ground_truth_sensitivity(pairs, frames, S, {"a": Info("a")}, 4, 4).empty


# ------------------------------------------------------------------- 07 / 13: the dictionary
def test_operating_points_compose_the_dictionary_stages(tmp_path):
    from greenloop.methods.dictionary import cnn, spots
    rng = np.random.default_rng(0)
    places = rng.random((4, 32, 32, 1)).astype(np.float32)
    X = np.concatenate([places.repeat(5, 0), places[:2].repeat(5, 0)])            # 30 frames: spots 0..5, 4 and 5 revisit 0 and 1
    X = X + 0.05 * rng.random(X.shape).astype(np.float32)
    frames = np.arange(0, 30, 2)
    gt = np.zeros((15, 15), bool)
    gt[np.ix_(np.arange(0, 5), np.arange(10, 15))] = True
    gt |= gt.T
    q = np.arange(15) >= 8
    det, points = dictionary.operating_points(X, 5, [3, 5], frames, gt, exclude=6, exclude_steps=3, n_train=20,
                                              queries=q, seed=0, progress=False, epochs=2, batch_size=8, cache=tmp_path)
    y = spots.group(30, 5)
    assert np.array_equal(det.labels, y) and det.n_train == 20
    assert np.concatenate([det.run["split"]["train"], det.run["split"]["test"]]).max() < 20   # frames before n_train only
    assert np.array_equal(det.pred, cnn.predict(det.run["model"], X))
    for p, tau in zip(points, [3, 5]):
        D = dictionary.declared_pairs(det.pred, y, tau, 6)[np.ix_(frames, frames)]
        assert p["tau"] == tau and p["op"] == evaluate.operating_point(D, gt, 3, queries=q)
        assert p["closures"] == dictionary.query_closures(D, gt, queries=q)
        assert p["flagged_frames"] == int(dictionary.run(det.pred, int(max(y.max(), det.pred.max()) + 1), tau).sum())
    assert points[0]["op"]["tp"] + points[0]["op"]["fp"] > 0          # the dictionary declared pairs at tau 3
    with pytest.raises(ValueError, match="n_train"):
        dictionary.operating_points(X, 5, [3], frames, gt, n_train=31)


def test_best_of_returns_the_result_and_the_shortest_time():
    calls = []
    out, secs = timing.best_of(lambda a: calls.append(a) or len(calls), 7, repeats=3)
    assert out == 3 and calls == [7, 7, 7] and 0 <= secs < 1
    with pytest.raises(ValueError, match="repeats"):
        timing.best_of(len, [], repeats=0)


# ----------------------------------------------------------------------------- 09: RGB-D
def test_split_backbones_keeps_the_cnns():
    assert rgbd_features.split_backbones(["ghostnet", "sift_bovw", "mobilenetv2:random", "pixels"]) == (
        ["ghostnet", "mobilenetv2:random"], ["sift_bovw", "pixels"])


def test_rgbd_table_scores_the_halves_of_extract_rgbd(tmp_path):
    from greenloop import features
    folder = _pose_folder(tmp_path / "seq", n=12)
    (folder / "depth").mkdir()
    rng = np.random.default_rng(0)
    for i in range(12):
        cv2.imwrite(str(folder / "depth" / f"{i}.png"), rng.integers(0, 20000, (30, 40), dtype=np.uint16))
    GT = np.zeros((12, 12), bool)
    GT[0, 11] = GT[11, 0] = GT[1, 10] = GT[10, 1] = True
    table, S, infos = rgbd_features.rgbd_table(folder, ["ghostnet", "mobilenetv3small"], GT, 2, weights=None, input_size=32)
    X = features.extract_rgbd(folder, "mobilenetv3small", None, progress=False, input_size=32)
    want = similarity.rgbd_matrices(X)
    t = table.set_index("backbone")
    for k in ("RGB", "depth", "RGB-D"):
        assert np.allclose(S["mobilenetv3small"][k], want[k], atol=1e-5)
        assert t.loc["mobilenetv3small", f"AP_{k}_%"] == pytest.approx(100 * evaluate.average_precision(want[k], GT, 2), abs=1e-6)
    g = t.loc["ghostnet"]
    assert g["R_a_%"] == 0 and g["R_t_%"] == 0 and t.loc["mobilenetv3small", "dim_rgbd"] == X.shape[1]
    m = t.loc["mobilenetv3small"]
    assert m["R_a_%"] == pytest.approx(100 * (m["AP_RGB-D_%"] - g["AP_RGB-D_%"]) / g["AP_RGB-D_%"])
    skipped = rgbd_features.skipped_table(["ghostnet"], None)
    assert skipped.to_dict("records") == [{"backbone": "ghostnet", "weights": "random init", "label": "ghostnet (random init)",
                                           "status": "skipped: the dataset has no depth/ folder"}]



def test_paper_vs_run_rounds_a_measured_number_to_its_decimals():
    from greenloop import report
    t = report.paper_vs_run([("a", 1, 2.34567, "n", 2), ("b", None, "text", "", 1), ("c", 2, np.float64(1.23456), "", 3),
                             ("d", 3, 7.891)])
    assert t["this run"].tolist() == [2.35, "text", 1.235, 7.891] and t.note.tolist() == ["n", "", "", ""]
    assert t.paper.tolist() == [1, "", 2, 3]
