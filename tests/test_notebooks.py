"""Every notebook, executed by papermill on tiny parameters, must run and write its results."""
import json
import os
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from greenloop.experiments import siamese_rgbd
from greenloop.methods.greenloop_seq import seqmatch
from greenloop.cli import main as cli_main
from greenloop.study import targets
from conftest import execute_notebook

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))
TINY = yaml.safe_load((ROOT / "params" / "tiny.yaml").read_text())
# per-notebook parameters over TINY in every run of that notebook: what its checks need and no more
OVERRIDES = {
    # two 64x64 CNNs, GhostNet among them (Tables 3/4's R_a reference), each described on RGB and depth;
    "09_rgbd_features": {"backbones": ["ghostnet", "mobilenetv3small"]},
    # the layer rows' tuning, stream and timing on a 224-wide network took half of 13's run: their entry
    # is checked in tests/test_detectors.py, their descriptors in 07's tiny run and tests/test_layers.py
    # frame_step 4 as make quick's 8 on a short recording: 13 must come down to every frame (the tiny sequence's
    # evaluation part holds 26 revisit queries at step 1, 4 at step 4), so its rows are those of step 1
    "13_leaderboard": {"layer_backbones": [], "frame_step": 4},
    # Table 1 under the early-stopping rule, capped at a few epochs
    "01_spot_grouping": {"stop_patience": 2, "stop_cap": 6},
    # the dictionary over seeds with notebook 01's early stopping (Nordland's profile sets it for 02-05)
    "05_dictionary_threshold": {"stop_patience": 1, "stop_cap": 3},
}


def _params(stem) -> dict:
    """The tiny parameters notebook `stem` runs on: TINY with its OVERRIDES."""
    return {**TINY, **OVERRIDES.get(stem, {})}


def _results_folder(tmp_path_factory, shared_cache, name: str) -> Path:
    """A results folder for one fixture sequence's runs; its models/ (each run's GREENLOOP_CACHE) is
    the session's shared cache, whose keys hash the data: a network, descriptor or converted graph
    that two sequences or two xdist workers need is computed once."""
    folder = tmp_path_factory.mktemp(name)
    (folder / "models").symlink_to(shared_cache, target_is_directory=True)
    return folder


@pytest.fixture(scope="module")
def results(tmp_path_factory, shared_cache):
    return _results_folder(tmp_path_factory, shared_cache, "results")


NOISE = re.compile(r"it/s\]|s/it\]|\d+%\|[#\u2588 ]|oneDNN|cuInit|cudart|Skipping variable loading|retracing"
                   r"|site-packages/|\.py:\d+: \w*Warning|/root/|\.keras/models")


def _noise(path) -> list[str]:
    """Lines of an executed notebook's outputs that are progress bars, library logs or paths into
    the environment: a reader must not scroll past them (they belong in the terminal)."""
    lines = []
    for cell in json.loads(Path(path).read_text())["cells"]:
        for o in cell.get("outputs", []):
            text = "".join(o.get("text", "")) + "".join(o.get("traceback", []))
            lines += [line[:160] for line in text.splitlines() if NOISE.search(line)]
    return lines


def _run(notebook, dataset, results, monkeypatch, parameters=None) -> Path:
    """Execute one notebook on `dataset` into `results` (on TINY, or on `parameters` instead, with the
    notebook's OVERRIDES over either);
    check what every notebook must write."""
    monkeypatch.setenv("PYTHONPATH", str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    monkeypatch.setenv("GREENLOOP_CACHE", str(results / "models"))
    monkeypatch.setenv("TF_CPP_MIN_LOG_LEVEL", "2")
    out = results / notebook.name
    execute_notebook(notebook, out, cwd=str(ROOT),
                     parameters=dict(TINY if parameters is None else parameters, **OVERRIDES.get(notebook.stem, {}),
                                     dataset=str(dataset), results_dir=str(results)))
    noise = _noise(out)
    assert not noise, f"progress bars or log lines in the executed notebook: {noise[:3]}"
    folder = results / notebook.stem
    assert (folder / "manifest.json").is_file()
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["dataset"] == str(dataset)
    assert list(folder.glob("*.md")), "the notebook wrote no table"
    assert list(folder.glob("*.png")), "the notebook saved no figure"
    if (folder / "paper_vs_run.csv").is_file():
        table = pd.read_csv(folder / "paper_vs_run.csv")
        assert list(table.columns[:3]) == ["quantity", "paper", "this run"]
        assert table["this run"].notna().all()
    return folder


# Which fixture sequences each notebook runs on, and why: declared here, one line per notebook (not
# grepped from the notebooks' source), so a notebook is never left out of a run by a regex.
# tiny: tiny_sequence (poses, depth); pairs: tiny_pairs_sequence (ground_truth.csv only, no poses, no
# depth); end_loop: tiny_end_loop_sequence (one revisit in the last 20 frames: the tuning/evaluation
# split); near_loop: tiny_near_loop_sequence with make's implied exclude; no_counted_loop: the same
# sequence at exclude = 150 (no loop left, for the notebooks make never skips).
RUNS = {
    "00_dataset": ("tiny", "pairs", "near_loop", "no_counted_loop", "days"),   # poses/depth when present; exclude; the days
    "01_spot_grouping": ("tiny",),                                     # labels by frame index only
    "02_training_over_seeds": ("tiny",),                               # labels by frame index only
    "03_confusion_matrix": ("tiny", "pairs", "near_loop", "no_counted_loop"),   # same-place errors from the ground truth
    "04_shift_robustness": ("tiny",),                                  # image shifts, no ground truth
    "05_dictionary_threshold": ("tiny", "pairs", "near_loop", "no_counted_loop"),   # trajectory figure when posed
    "06_speed": ("tiny",),                                             # timing only
    "07_feature_baselines": ("tiny", "pairs"),                         # Eq. 5 rows need poses; pairs without
    "08_descriptor_postprocessing": ("tiny", "end_loop"),              # tunes on one part of the revisits
    "09_rgbd_features": ("tiny", "pairs"),                             # skips the depth rows without depth/
    "10_siamese_rgbd": ("tiny", "end_loop"),                           # end_loop: no depth/ (fusions skipped); splits
    "11_lsh_matching": ("tiny", "pairs"),                              # pose ground truth or pairs
    "12_revisit_protocol": ("tiny", "end_loop", "near_loop"),          # first traversal / revisit split
    "13_leaderboard": ("tiny", "end_loop", "days"),                    # tuning/evaluation split; the days' splits
}
SEQUENCES = {"tiny", "pairs", "end_loop", "near_loop", "no_counted_loop", "days"}
# days: tiny_days_sequence, the greenhouse over two days (--tiny --days 2): 00 shows each day's frames and
# what the renderer models, 13 splits its rows by day, direction and light (splits.csv)
# near_loop (a traversals/ folder whose loops lie inside the default window, exclude implied by
# study.params): 07, 08, 09, 10 and 11 read that folder's loop pairs as their pairs run reads
# ground_truth.csv, and hand exclude to their experiment functions unchanged, so it would repeat
# their pairs run (about 70 s of the suite); so does 13, whose exclude goes to leaderboard.prepare
# unchanged (its end_loop run splits at exclude 20); the other notebooks with an exclude keep it.


def _on(sequence) -> list[Path]:
    """The notebooks that RUNS says run on `sequence`, in order."""
    return [p for p in NOTEBOOKS if sequence in RUNS.get(p.stem, ())]


def test_every_notebook_declares_the_sequences_it_runs_on():
    """A new notebook must get its line in RUNS (and a removed one lose it)."""
    assert sorted(RUNS) == [p.stem for p in NOTEBOOKS]
    assert all(r and r[0] == "tiny" and set(r) <= SEQUENCES for r in RUNS.values()), RUNS


@pytest.mark.notebook
@pytest.mark.parametrize("notebook", _on("tiny"), ids=[p.stem for p in _on("tiny")])
def test_notebook_runs_and_writes_results(notebook, tiny_sequence, results, monkeypatch):
    folder = _run(notebook, tiny_sequence, results, monkeypatch)
    CHECKS.get(notebook.stem, lambda f: None)(folder)


@pytest.fixture(scope="module")
def pair_results(tmp_path_factory, shared_cache):
    return _results_folder(tmp_path_factory, shared_cache, "results-pairs")


@pytest.mark.notebook
@pytest.mark.parametrize("notebook", _on("pairs"), ids=[p.stem for p in _on("pairs")])
def test_notebook_runs_without_poses_or_depth(notebook, tiny_pairs_sequence, pair_results, monkeypatch):
    """The same notebooks on a sequence whose ground truth is only ground_truth.csv (no poses,
    no depth): the parts that need poses or depth are skipped, the rest runs and writes."""
    # 07's layer study runs in its tiny run; here an empty layer_backbones (the study says so and skips)
    folder = _run(notebook, tiny_pairs_sequence, pair_results, monkeypatch,
                  parameters=dict(TINY, layer_backbones=[]) if notebook.stem.startswith("07") else None)
    assert json.loads((folder / "manifest.json").read_text())["dataset_ground_truth"] == "pairs"
    {**CHECKS, **PAIR_CHECKS}.get(notebook.stem, lambda f: None)(folder)


@pytest.fixture(scope="module")
def days_results(tmp_path_factory, shared_cache):
    return _results_folder(tmp_path_factory, shared_cache, "results-days")


@pytest.mark.notebook
@pytest.mark.parametrize("notebook", _on("days"), ids=[p.stem for p in _on("days")])
def test_notebook_runs_on_the_greenhouse_days(notebook, tiny_days_sequence, days_results, monkeypatch):
    """00 and 13 on the tiny two-day render, at the exclude its sequence.yaml states (as make passes it)."""
    from greenloop.datasets import sequence
    folder = _run(notebook, tiny_days_sequence, days_results, monkeypatch,
                  parameters=dict(TINY, exclude=sequence.open(tiny_days_sequence).exclude))
    DAYS_CHECKS[notebook.stem](folder)


def _check_days_00(folder):
    """Every day's frames of each place side by side, and the renderer's scope printed from its constants."""
    from greenloop.datasets.synthetic import dayscene
    t = pd.read_csv(folder / "days_frames.csv")
    assert t.day.tolist() == ["day-00", "day-01"] * 2 and t.place.tolist() == ["aisle 0"] * 2 + ["aisle 1"] * 2
    assert t.same_direction.tolist() == [True, True, True, False] and (folder / "days.png").is_file()
    text = (folder.parent / "00_dataset.ipynb").read_text()
    assert all(json.dumps(x)[1:-1] in text for x in dayscene.NOT_MODELLED)


def _check_days_13(folder):
    """splits.csv: every scored loop-closure row's R@1 over all revisit queries is the leaderboard's, on
    the same queries; within + across days is every revisit query; the figure is saved."""
    t = pd.read_csv(folder / "leaderboard.csv")
    lc = t[(t["mode"] == "loop closure")].dropna(subset=["R@1_%"]).set_index("method").drop(index="chance (random scores)")
    s = pd.read_csv(folder / "splits.csv")
    assert set(s.method) == set(lc.index) and (folder / "splits.png").is_file() and (folder / "splits.md").is_file()
    for name, g in s.groupby("method"):
        c = g.set_index(["split", "cell"])
        assert c.loc[("all", "revisit queries"), "queries"] == lc.loc[name, "revisit_queries"], name
        assert abs(c.loc[("all", "revisit queries"), "R@1_%"] - lc.loc[name, "R@1_%"]) <= 0.011, name
        day = c.loc["day"]
        assert day.queries.sum() == lc.loc[name, "revisit_queries"] and day.hits.sum() == c.loc[("all", "revisit queries"), "hits"]
        assert c.loc[("day", "across days"), "queries"] > 0 and c.loc[("all", "evaluation queries"), "queries"] == lc.loc[name, "queries"]
        assert set(g.split) == {"all", "day", "direction", "light", "query day"} and set(c.loc["light"].index) == {"sun", "overcast"}
        assert c.loc["query day"].queries.sum() == lc.loc[name, "revisit_queries"]


DAYS_CHECKS = {"00_dataset": _check_days_00, "13_leaderboard": _check_days_13}


def _check_01(folder):
    t = pd.read_csv(folder / "table1.csv")
    assert t.frames_per_spot.tolist() == TINY["frames_per_spot_list"]
    assert t.spots.tolist() == [-(-200 // L) for L in TINY["frames_per_spot_list"]]
    L = t.frames_per_spot
    assert (t.last_spot_frames == 200 - (t.spots - 1) * L).all()
    seeds = np.where(L == TINY["frames_per_spot"], len(TINY["seeds"]), len(TINY["seeds_per_grouping"]))
    assert (t.seeds == seeds).all() and (t["acc_std_%"] >= 0).all()      # the paper's L runs `seeds`
    for c in ("acc_mean_%", "acc_median_%"):            # a mean or median of the seeds lies between their extremes
        assert (t["acc_min_%"] <= t[c] + 0.005).all() and (t[c] <= t["acc_max_%"] + 0.005).all(), c
    assert (t.converged_seeds <= t.seeds).all()
    assert (t.epochs_min <= t.epochs_max).all() and (t.epochs_max <= 6).all() and (t.epochs_min >= 3).all()
    assert (t.budget_limited == (2 * t.converged_seeds < t.seeds)).all()
    c = pd.read_csv(folder / "table1_control_runs.csv")
    assert sorted(c.frames_per_spot.unique()) == sorted(TINY["frames_per_spot_list"])
    for L, d in c.groupby("frames_per_spot"):          # the matched control has the blocked split's size
        b, m = (d[d.control == k].set_index("seed").n_train for k in ("blocked", "random, same n_train"))
        assert b.equals(m) and (b < 200 * 0.8).all()
    s = pd.read_csv(folder / "table1_controls.csv").set_index(["frames_per_spot", "control"])
    assert len(s) == 3 * len(TINY["frames_per_spot_list"])
    g = c.groupby(["frames_per_spot", "control"])          # the summary, recomputed from the per-run rows
    want = pd.DataFrame({"seeds": g.size(), "converged_seeds": g.converged.sum(), "n_train_median": g.n_train.median(),
                         "acc_median_%": g["test_acc_%"].median(), "acc_min_%": g["test_acc_%"].min(),
                         "acc_max_%": g["test_acc_%"].max(),
                         "acc_median_converged_%": g.apply(lambda d: d.loc[d.converged, "test_acc_%"].median())})
    got = s.loc[want.index, want.columns].astype(float)
    assert np.allclose(got, want.astype(float), atol=0.006, equal_nan=True), (got, want)


def _check_02(folder):
    t = pd.read_csv(folder / "per_seed.csv")
    assert sorted(t.split.unique()) == ["blocked", "random"]
    assert len(t) == 2 * len(TINY["seeds"])
    c = pd.read_csv(folder / "leakage_controls.csv")
    assert set(c.control) == {"blocked", "random, same n_train", "blocked, centred"}
    blocked = c[c.control == "blocked"].set_index(["gap", "seed"]).n_train
    matched = c[c.control == "random, same n_train"].set_index(["gap", "seed"]).n_train
    assert blocked.equals(matched)                     # the control has the blocked split's training-set size
    by_gap = blocked.groupby("gap").min()
    assert by_gap.index.tolist() == TINY["sweep_gaps"] and by_gap.is_monotonic_decreasing
    # the budget label stands on the table exactly where fewer than half of the seeds converged
    label = f"budget-limited: {int(t.converged.sum())} of {len(t)} seeds converged"
    assert (label in (folder / "per_seed.md").read_text()) == (2 * t.converged.sum() < len(t))


def _budget_labelled(md, runs: int) -> None:
    """A table's budget label, where it has one, counts every run it rests on."""
    m = re.search(r"budget-limited: (\d+) of (\d+) seeds converged", md)
    assert m is None or (int(m[2]) == runs and 2 * int(m[1]) < runs), m


def _check_03(folder):
    t = pd.read_csv(folder / "table2.csv")
    assert len(t) == -(-200 // TINY["frames_per_spot"])
    e = pd.read_csv(folder / "errors_per_seed.csv")
    assert (e.test_frames == 40).all()
    assert sorted(e.split.unique()) == ["blocked", "random"] and len(e) == 2 * len(TINY["seeds"])
    assert len(pd.read_csv(folder / "table2_blocked.csv")) == len(t)
    _budget_labelled((folder / "errors_per_seed.md").read_text(), 2 * len(TINY["seeds"]))


def _check_04(folder):
    from greenloop.methods.dictionary import shift
    _budget_labelled((folder / "table3.md").read_text(), len(TINY["seeds"]))
    t = pd.read_csv(folder / "shift_controls.csv")
    assert t.input.unique().tolist() == list(shift.CONTROLS)
    assert len(t) == 4 * 4 * len(shift.CONTROLS)                   # 4 directions x shifts 1, 2, 4, 8
    assert t["accuracy_mean_%"].between(0, 100).all()
    assert t.changed_pixels_per_frame.between(0, 32 * 32).all() and t.mean_abs_change_per_pixel.between(0, 1).all()
    one = t[(t.shift_px == 1) & (t.direction == "right")].set_index("input")
    assert one.loc["replicate border", "mean_abs_change_per_pixel"] < one.loc["zero border (paper)", "mean_abs_change_per_pixel"]
    # 160x120 -> 32x32: 5 full-res px per input column, so horizontal full-res zero-border shifts equal the paper's
    assert one.loc["full-res shift, zero border", "accuracy_mean_%"] == one.loc["zero border (paper)", "accuracy_mean_%"]
    w = pd.read_csv(folder / "shift_controls_1px.csv")
    assert w.direction.tolist() == ["right", "left", "down", "up"]
    tf = pd.read_csv(folder / "training_frames.csv")
    assert tf.frames.tolist() == ["all frames (the paper's protocol)", "training frames only", "held-out test frames only"]
    assert tf.n_frames.tolist()[0] == 200 and tf.shift1_vs_test_only_points.iloc[-1] == 0
    t3 = pd.read_csv(folder / "table3.csv")
    assert abs(tf["shift1_%"].iloc[0] - t3["shift1_all_frames_%"].mean()) < 0.01
    p = pd.read_csv(folder / "perturbations.csv").set_index(["perturbation", "amount"])
    assert abs(p.loc[("shift right", 1), "heldout_mean"] - t3["shift1_test_only_%"].mean()) < 0.01   # the same shift
    assert abs(p.loc[("shift right", 1), "all_frames_mean"] - t3["shift1_all_frames_%"].mean()) < 0.01
    cmp = pd.read_csv(folder / "paper_vs_run.csv").set_index("quantity")
    assert cmp.loc["accuracy, held-out test frames shifted 1 px right (%)", "note"].startswith("judged")
    assert (folder / "shift_controls.png").is_file()


def _check_05(folder):
    s = json.loads((folder / "summary.json").read_text())
    assert s["derived"]["tau"] == TINY["frames_per_spot"] + 10
    t = pd.read_csv(folder / "tau_sweep.csv")
    assert sorted(t.tau.unique()) == TINY["tau_list"]
    tau = s["derived"]["tau"]
    assert tau in TINY["tau_list"] and set(t.variant) == set(s["scores"])
    for variant, d in t.groupby("variant"):
        d = d.sort_values("tau")
        flagged = d.true_frames + d.false_frames          # a higher threshold can only flag fewer frames
        assert flagged.is_monotonic_decreasing and d.true_frames.is_monotonic_decreasing, variant
        at = d.set_index("tau").loc[tau]                   # the sweep's row at the derived tau is the scored one
        sc = s["scores"][variant]
        assert (at.true_events, at.false_events, at.true_frames, at.false_frames) == (
            sc["true_events"], sc["false_events"], sc["true_frames"], sc["false_frames"]), variant
        assert at["revisit_recall_%"] == pytest.approx(100 * sc["revisits_detected"] / max(1, sc["revisit_frames"]), abs=0.06)
    per_seed = pd.read_csv(folder / "seeds.csv")               # the detector with every seed's CNN
    assert sorted(per_seed.seed.unique()) == TINY["seeds"] and len(per_seed) == 2 * len(TINY["seeds"])
    summ = pd.read_csv(folder / "seeds_summary.csv").set_index("variant")
    assert (summ.seeds == len(TINY["seeds"])).all()
    assert summ.converged_seeds.tolist() == per_seed.groupby("variant", sort=False).converged.sum().tolist()
    assert per_seed.epochs.between(2, OVERRIDES["05_dictionary_threshold"]["stop_cap"]).all()   # early stopping, capped
    first = per_seed[per_seed.seed == TINY["seeds"][0]].set_index("variant")
    for variant, sc in s["scores"].items():                  # the figures' seed is the table's first
        assert first.loc[variant, "true_events"] == sc["true_events"], variant
        assert sc["revisits_detected"] <= sc["revisit_frames"]


def _check_06(folder):
    s = json.loads((folder / "summary.json").read_text())
    assert s["repeats"] == TINY["repeats"]
    n, med, p95 = s["window_frames"], s["median_window_s"], s["p95_window_s"]
    assert n == json.loads((folder / "manifest.json").read_text())["parameters"]["window"]   # 70 <= 200 frames
    assert 0 < med <= p95                                       # a median never exceeds the 95th percentile
    # the rates are the window's median time per frame, not some other time
    assert s["frames_per_s"] == pytest.approx(n / med) and s["median_ms_per_frame"] == pytest.approx(1000 * med / n)
    assert s["p95_ms_per_frame"] == pytest.approx(1000 * p95 / n)
    cmp = pd.read_csv(folder / "paper_vs_run.csv").set_index("quantity")["this run"]
    assert str(cmp["frames per second"]) == f"{s['frames_per_s']:.0f}"


def _feature_backbones(stem="07_feature_baselines"):
    """The backbones notebook `stem`'s tiny run describes (TINY's, or its OVERRIDES')."""
    return list(_params(stem)["backbones"])


def _check_07_layers(folder):
    """The layer study: every depth x pooling of each layer network, scored on both query parts,
    and per network the row with the highest tuning AUC-PR chosen (the tiny sequence splits)."""
    from greenloop.features import layers
    t = pd.read_csv(folder / "layers.csv")
    nets = TINY["layer_backbones"]
    assert t.backbone.tolist() == [b for b in nets for _ in range(len(layers.DEPTHS) * len(layers.POOLINGS))]
    assert sorted(set(zip(t.depth, t.pooling))) == sorted((d, p) for d in layers.DEPTHS for p in layers.POOLINGS)
    assert t.filter(regex="_(tune|eval)_%$").stack().between(0, 100).all() and not t.filter(like="_all_").size
    for _, g in t.groupby("backbone"):
        assert g.chosen.sum() == 1
        assert g.loc[g.chosen, "AUC-PR_tune_%"].iloc[0] == g["AUC-PR_tune_%"].max()
    grid, avg = t[t.pooling == "grid2"].set_index(["backbone", "depth"]), t[t.pooling == "avg"].set_index(["backbone", "depth"])
    assert (grid.dim == 4 * avg.dim).all()
    assert (t.input == "224x176").all()                # 160x120 frames: 224 wide, 168 high rounded up to 16s


def _check_07(folder):
    t = pd.read_csv(folder / "table2.csv")
    g = pd.read_csv(folder / "ap_vs_ground_truth.csv").set_index("ground_truth")
    assert g.loop_pairs.loc["Eq. 5 < 0.3"] <= g.loop_pairs.loc["Eq. 5 < 0.5"] <= g.loop_pairs.loc["Eq. 5 < 0.8"]
    assert (g.loc["Eq. 5 < 0.5", t.label].values == t["AP_%"].values).all()   # the main table's definition
    _check_07_table(folder)
    _check_07_layers(folder)


def _check_07_pairs(folder):
    """Without poses there is no Eq. 5 threshold to vary: no ap_vs_ground_truth table, the rest as posed;
    without layer networks the layer table is empty and no layer row joins Table 2."""
    assert not (folder / "ap_vs_ground_truth.csv").exists()
    assert pd.read_csv(folder / "layers.csv").empty and (folder / "layers.png").is_file()
    _check_07_table(folder)


def _pixels_ap(folder) -> float:
    """The pixels row's AP (%) recomputed outside the notebook: its descriptors (uncached), their
    cosine matrix and sklearn's average_precision_score over the pairs j - i > exclude steps."""
    from sklearn.metrics import average_precision_score

    from greenloop import features, groundtruth
    m = json.loads((folder / "manifest.json").read_text())
    p = m["parameters"]
    _, ex, gt, _ = groundtruth.described_frames(m["dataset"], p["frame_step"], p["loop_threshold"], p["exclude"])
    f, _ = features.extract_all(m["dataset"], ["pixels"], None, p["input_size"], step=p["frame_step"], cache=False)
    f = f["pixels"] / np.linalg.norm(f["pixels"], axis=1, keepdims=True)
    i, j = np.triu_indices(len(f), ex + 1)
    return 100 * average_precision_score(np.asarray(gt)[i, j], (f @ f.T)[i, j])


def _assert_relative_accuracy(by, ref, ap):
    """R_a_% (Qi 2024: 100 (AP - AP_ref) / AP_ref) recomputed from the table's own APs, rounded to
    2 decimals (hence the tolerance: the rounding of both APs, then of R_a to 1 decimal); 0 on ref."""
    a, r = by[ap], by.loc[ref, ap]
    assert by.loc[ref, "R_a_%"] == 0
    assert np.allclose(by["R_a_%"], 100 * (a / r - 1), atol=0.06 + 0.6 * (1 / r + a / r ** 2)), by[[ap, "R_a_%"]]


def _check_07_table(folder):
    t = pd.read_csv(folder / "table2.csv")
    by = t.set_index("backbone")
    assert by.loc["pixels", "AP_%"] == pytest.approx(_pixels_ap(folder), abs=0.006)
    _assert_relative_accuracy(by, "sift_bovw", "AP_%")
    layers = pd.read_csv(folder / "layers.csv")
    chosen = layers[layers.chosen]
    # one row per backbone, in order, then each layer network's row chosen on the tuning queries
    from greenloop.features.layers import specs
    assert t.backbone.tolist() == _feature_backbones() + [specs([r.backbone], [r.depth], [r.pooling])[0]
                                                          for r in chosen.itertuples()]
    assert {"weights", "label"} <= set(t.columns)
    assert (t.label == t.backbone.str.split(":").str[0] + " (" + t.weights + ")").all()
    assert t["AP_%"].between(0, 100).all() and t["R@100P_%"].between(0, 100).all()
    assert t["R@1_%"].between(0, 100).all()
    assert (t.extract_s_per_image > 0).all() and (t.match_s_MxM > 0).all()
    controls = t[t.backbone.str.endswith(":random")]
    assert len(controls) and (controls.weights == "random init").all()
    fixed = controls[controls.backbone.str.startswith(("mobilenetv1", "mobilenetv2"))]   # the TFLite graphs
    assert (fixed.input == "224x224").all()                      # fixed input (tests/test_features.py too)
    assert (controls.drop(fixed.index).input == f"{TINY['input_size']}x{TINY['input_size']}").all()
    cnns = t[t.backbone.isin(["vgg19", "resnet50", "resnet101", "resnet152", "efficientnetb0", "ghostnet",
                              "mobilenetv3small"])]
    assert (cnns.weights == "random init").all()                 # tiny runs weights=None: never "imagenet"
    if "sift_bovw" in t.backbone.values:
        assert t.set_index("backbone").loc["sift_bovw", "R_a_%"] == 0
    ops = pd.read_csv(folder / "dictionary_operating_points.csv")
    assert ops.tau.tolist() == TINY["tau_list"]
    assert ops.recall.between(0, 1).all()


def _check_08(folder):
    t = pd.read_csv(folder / "postprocessing.csv")
    done = [b for b in _feature_backbones("08_descriptor_postprocessing") if b != "spot_cnn"]
    assert sorted(t.backbone.unique()) == sorted(done)
    assert {"weights", "label"} <= set(t.columns)
    assert {"raw", "L2", "ZCA, tuned dim"} <= set(t.variant)
    assert t["AP_eval_%"].between(0, 100).all() and t["AP_tune_%"].between(0, 100).all()
    assert set(t["size"]) <= set(TINY["median_sizes"])
    assert t["MPCA_eval"].between(0, 1).all()                 # mean per-class accuracy, threshold tuned
    # ZCA is PCA whitening rotated back (W_zca = U W_pca, U orthogonal): the same cosines, so the same APs
    # wherever both picked the same dim (up to float near-ties of the scores)
    k, ap = ["backbone", "median_filter"], ["AP_tune_%", "AP_eval_%"]
    pca = t[t.variant == "PCA-whitened, tuned dim"].set_index(k)
    zca = t[t.variant == "ZCA, tuned dim"].set_index(k).loc[pca.index]
    same = pca.whitening == zca.whitening
    assert same.any() and np.allclose(pca.loc[same, ap], zca.loc[same, ap], atol=0.25), (pca[ap], zca[ap])
    # a median filter of size 1 is the identity: its rows equal the unfiltered ones
    k = ["backbone", "variant"]
    one = t[(t.median_filter == "median (tuned)") & (t["size"] == 1)].set_index(k)
    none = t[t.median_filter == "none"].set_index(k).loc[one.index]
    assert np.allclose(one[ap + ["R@100P_eval_%"]], none[ap + ["R@100P_eval_%"]], atol=1e-9)
    two = pd.read_csv(folder / "second_split.csv")             # knobs re-picked with the parts swapped
    assert two.split.nunique() == 2 and len(two) == 2 * 2 * len(done)
    assert set(two[two.knob == "median size, L2"].picked) <= set(TINY["median_sizes"])
    for fig in ("pr_raw_vs_whitened", "similarity_raw_vs_whitened"):   # Zhang 2017 Figs. 5 and 4
        assert (folder / f"{fig}.png").stat().st_size > 0
    tuning = pd.read_csv(folder / "tuning.csv")
    assert (tuning.knob == "pca dim").any() and tuning.knob.str.startswith("median size").any()
    m = json.loads((folder / "manifest.json").read_text())
    assert m["parameters"]["tune_frames"] > 0 and m["parameters"]["eval_frames"] > 0
    p = pd.read_csv(folder / "paired.csv")                     # the papers' orders, paired over the same queries
    assert sorted(p.backbone.unique()) == sorted(done) and len(p) == 3 * 2 * len(done)
    assert (p.low <= p.difference).all() and (p.difference <= p.high).all() and (p.blocks >= 1).all()
    assert (p.resolved == ((p.low > 0) | (p.high < 0))).all() and all(r == targets.paired_word(lo, hi) for r, lo, hi in zip(p.result[~p.resolved], p.low[~p.resolved], p.high[~p.resolved]))
    one = p[p.comparison == "ZCA + median filter (tuned) minus ZCA"].merge(
        t[(t.variant == "ZCA, tuned dim") & (t.median_filter != "none")][["backbone", "size"]], on="backbone")
    assert (one[one["size"] == 1].result == "tie").all()       # a median filter of size 1 changes nothing


def _check_09(folder):
    t = pd.read_csv(folder / "rgbd.csv")
    cnns = [b for b in _params("09_rgbd_features")["backbones"] if b not in ("sift_bovw", "pixels", "spot_cnn")]
    assert t.backbone.tolist() == cnns
    assert (t.weights == "random init").all()
    for c in ("AP_RGB_%", "AP_depth_%", "AP_RGB-D_%"):
        assert t[c].between(0, 100).all()
    _assert_relative_accuracy(t.set_index("backbone"), "ghostnet", "AP_RGB-D_%")   # Tables 3/4: against GhostNet
    p = pd.read_csv(folder / "paired.csv")                     # RGB-D minus RGB on the same queries
    assert p.backbone.tolist() == [b for b in cnns for _ in range(2)] and set(p.comparison) == {"RGB-D minus RGB"}
    assert (p.low <= p.difference).all() and (p.difference <= p.high).all()
    d = pd.read_csv(folder / "paper_vs_run.csv")
    assert len(d) > 0


def _check_11(folder):
    t = pd.read_csv(folder / "table6.csv")
    done = [b for b in _feature_backbones("11_lsh_matching") if b != "spot_cnn"]
    assert t.backbone.unique().tolist() == done
    assert (t.label == t.backbone.str.split(":").str[0] + " (" + t.weights + ")").all()
    variants = ["brute force", "NearestNeighbors (sklearn)", "SWP-RHLSH", "QDP-RHLSH", "SWP-RHLSH, centred",
                "QDP-RHLSH, centred"]
    assert (t.groupby("backbone", sort=False).variant.apply(list) == pd.Series([variants] * len(done), done)).all()
    per_query = ["R@1_%", "AUC-PR_%", "R@100P_%", "R@95P_%"]
    assert "AP_best_%" not in t.columns and list(t.columns[5:9]) == per_query     # the field's metrics first
    for c in per_query + ["AP_pairs_%", "NN_agree_%", "scanned_%"]:
        assert t[c].between(0, 100).all(), c
    assert (t["R@95P_%"] >= t["R@100P_%"]).all() and (t.ms_per_query > 0).all()
    s = json.loads((folder / "summary.json").read_text())
    by = t.set_index(["backbone", "variant"])
    for b in done:                                  # exact methods: the full matrix's scores, every frame scanned
        for v in ("brute force", "NearestNeighbors (sklearn)"):
            assert abs(by.loc[(b, v), "AP_pairs_%"] - s["ap_full_%"][b]) < 1e-3
            # the matrix path's R@1, up to one query whose best match flips on a float near-tie of two cosines
            assert abs(by.loc[(b, v), "R@1_%"] - s["per_query_full_%"][b]["R@1"]) <= 100 / s["revisit_frames"] + 1e-3
            assert abs(by.loc[(b, v), "AUC-PR_%"] - s["per_query_full_%"][b]["AUC-PR"]) <= 100 / s["revisit_frames"] + 1e-3
            assert by.loc[(b, v), "scanned_%"] == 100 and by.loc[(b, v), "NN_agree_%"] == 100
        assert by.loc[(b, "brute force"), "R_a_%"] == 0
        assert by.loc[(b, "SWP-RHLSH"), "probes_per_query"] == 2517           # 16 bits, radius 4
        assert by.loc[(b, "QDP-RHLSH"), "probes_per_query"] <= 1501
    seeds = pd.read_csv(folder / "per_seed.csv")
    assert sorted(seeds[seeds.variant == "SWP-RHLSH"].seed.unique()) == TINY["lsh_seeds"]
    sc = pd.read_csv(folder / "scaling.csv")          # the committed make bench-scale table, read as it is
    bench = pd.read_csv(ROOT / "results" / "bench" / "scale.csv")
    assert sc[["stored", "method", "p50_ms", "recall@1_%"]].equals(bench[["stored", "method", "p50_ms", "recall@1_%"]])
    cmp = pd.read_csv(folder / "paper_vs_run.csv")
    swp = cmp[cmp.iloc[:, 0].astype(str).str.startswith("stored frames from which SWP-RHLSH")]
    assert len(swp) == 1
    assert (folder / "figure7_pr_curves.png").is_file() and (folder / "scaling.png").is_file()


def _check_10(folder):
    seeds = TINY["siamese_seeds"]
    per_seed = pd.read_csv(folder / "supervisions_per_seed.csv")
    trained = per_seed[per_seed.train_pairs > 0]
    assert trained.supervision.tolist() == [x for x in ("softmax", "contrastive", "multitask") for _ in seeds]
    assert trained.seed.tolist() == seeds * 3
    assert (trained.weights == "trained here").all() and (trained.label.str.endswith("(trained here)")).all()
    assert (trained.train_pairs == TINY["siamese_epochs"] * TINY["siamese_pairs"]).all()
    assert (trained.dim == 128).all() and (trained.train_s > 0).all()
    assert set(per_seed.weights) == {"trained here", "random init", "none"}      # + untrained and pixels rows
    assert per_seed["AP_%"].between(0, 100).all() and per_seed["R@100P_%"].between(0, 100).all()
    assert (per_seed["AP_%"] == per_seed["AP_%"].round(2)).all()              # rounded where the table is written
    sup = pd.read_csv(folder / "supervisions.csv").set_index("descriptor")        # the summary over seeds
    g = per_seed.groupby("descriptor", sort=False)["AP_%"]
    assert list(sup.index) == list(g.mean().index) and (sup.seeds == g.size()).all()
    assert np.allclose(sup.AP_mean, g.mean(), atol=0.006) and (sup.AP_min == g.min()).all() and (sup.AP_max == g.max()).all()
    # one epoch: no training loss has levelled off, so every table and the conclusion say budget-limited
    assert (trained.converged == False).all() and (sup.loc[trained.descriptor.unique(), "converged_seeds"] == 0).all()  # noqa: E712
    label = f"budget-limited: 0 of {len(trained)} networks converged"
    assert label in (folder / "supervisions.md").read_text() and label in (folder / "supervisions_per_seed.md").read_text()
    fus = pd.read_csv(folder / "fusions_per_seed.csv")
    assert fus[fus.fusion == "mid"].layer.tolist() == [x for x in TINY["mid_layers"] for _ in seeds]
    assert {"early", "late", "RGB only", "late (rgb stream)", "late (depth stream)"} <= set(fus.fusion)
    assert (fus.weights == "trained here").all() and fus["AP_%"].between(0, 100).all()
    fsum = pd.read_csv(folder / "fusions.csv")
    assert (fsum.seeds == len(seeds)).all() and len(fsum) == len(fus) // len(seeds)
    t2 = pd.read_csv(folder / "table2_mid_level_layers.csv")
    assert t2.quantity.str.endswith(tuple(TINY["mid_layers"])).all() and len(t2) == len(TINY["mid_layers"])
    assert pd.to_numeric(t2["this run"]).between(0, 1).all() and t2.paper.notna().all()
    t = pd.read_csv(folder / "timing.csv")
    assert (t.s_per_image_batched > 0).all() and (t.s_per_image_one_at_a_time > 0).all()
    t3 = pd.read_csv(folder / "table3_extraction_time.csv").set_index("quantity")["this run"]
    for r in t.itertuples():                           # Table 3's cells are timing.csv's, neither column swapped
        assert t3[f"extraction time per image, CPU (s): {r.descriptor}"] == (
            f"{r.s_per_image_one_at_a_time:.5f} one at a time; {r.s_per_image_batched:.5f} batched"), r.descriptor
    s = json.loads((folder / "summary.json").read_text())
    assert s["labelled_frames_near_heldout"] == 0 and s["last_train_frame"] < s["first_heldout_frame"]
    assert s["networks_trained"] == (3 + 2 + len(TINY["mid_layers"])) * len(seeds)
    best = pd.read_csv(folder / "paper_vs_run.csv").set_index("quantity")["this run"]
    cell, _ = siamese_rgbd.best_cell(sup.reset_index(), [f"scnn {x}, RGB" for x in ("softmax", "contrastive", "multitask")])
    assert best["best supervision"] == cell
    assert best["best mid-level layer (Table 2)"] == siamese_rgbd.UNRESOLVED        # one layer is never best
    assert best[siamese_rgbd.LEVELLING].startswith("n/a") and TINY["siamese_epochs"] < 3     # no thirds to compare
    assert (folder / "convergence.png").is_file()
    # early stopping on, capped at one epoch: every network took its cap and none could stop before it
    assert (trained.epochs == 1).all() and (trained.epoch_cap == TINY["siamese_epochs"]).all()
    rule = pd.read_csv(folder / "paper_vs_run.csv").set_index("quantity").loc[siamese_rgbd.CONVERGED, "note"]
    assert rule.startswith("siamese.converged: early stopping on a held-out loss") and \
        f"of its best for {TINY['siamese_patience']} epochs" in rule
    assert best["epochs taken per network, min - median - max"] == f"1 - 1 - 1 (cap {TINY['siamese_epochs']})"
    ranked = siamese_rgbd.ranked_fusions(fus, TINY["mid_layers"])    # what Fig. 9's header and the verdict count
    assert set(ranked.fusion) == {"early", "mid", "late"} and len(ranked) == 3 * len(seeds)
    assert (sup.epochs_max.max(), sup.epochs_min.min()) == (1, 0)   # trained rows 1 epoch, the untrained 0


def _check_12(folder):
    per_seed = pd.read_csv(folder / "per_seed.csv")
    assert list(per_seed.columns) == ["split", "seed", "n_train", "epochs", "final_train_acc_%", "converged",
                                      "in_traversal_test_acc_%", "revisit_acc_%", "revisit_frames"]
    # converged: fit the training frames (or stopped rising; no early stopping here, so every epoch ran)
    assert (per_seed.epochs == TINY["epochs"]).all()
    assert per_seed.converged.equals(per_seed["final_train_acc_%"] >= 95)
    # the budget label on the tables and in the conclusion exactly where fewer than half of the runs converged
    label = f"budget-limited: {int(per_seed.converged.sum())} of {len(per_seed)} seeds converged"
    limited = 2 * per_seed.converged.sum() < len(per_seed)
    assert (label in (folder / "summary_table.md").read_text()) == limited
    assert json.loads((folder / "summary.json").read_text())["budget"] == (label if limited else "")
    assert sorted(map(tuple, per_seed[["split", "seed"]].values)) == sorted((s, k) for s in ("random", "blocked") for k in TINY["seeds"])
    acc = per_seed.filter(like="acc_%")
    assert acc.stack().between(0, 100).all() and (acc == acc.round(2)).all().all()
    summary = pd.read_csv(folder / "summary_table.csv")
    assert list(summary.columns) == ["split", "scored_on", "seeds", "mean", "std", "median", "min", "max"]
    assert (summary.seeds == len(TINY["seeds"])).all() and len(summary) == 4
    long = per_seed.melt(id_vars="split", value_vars=["in_traversal_test_acc_%", "revisit_acc_%"], var_name="scored_on")
    g = long.groupby(["split", "scored_on"]).value             # the summary, recomputed from the per-seed rows
    want = pd.DataFrame({"seeds": g.size(), "mean": g.mean(), "std": g.std(ddof=1), "median": g.median(),
                         "min": g.min(), "max": g.max()})
    got = summary.set_index(["split", "scored_on"]).loc[want.index, want.columns].astype(float)
    assert np.allclose(got, want.astype(float), atol=0.006), (got, want)
    d = pd.read_csv(folder / "dictionary_tuned.csv")
    assert d.tau_rule.tolist() == ["chosen on the tuning part", "paper: L + Δ"] * len(TINY["seeds"])
    assert d.tau[d.tau_rule.str.startswith("chosen")].isin(TINY["tau_list"]).all()
    assert (d[["precision", "recall"]].dropna() == d[["precision", "recall"]].dropna().round(4)).all().all()
    s = json.loads((folder / "summary.json").read_text())
    assert s["split"]["honest"] and s["revisit_frames"] == per_seed.revisit_frames.iloc[0] > 0


def _leaderboard_bounds(t):
    """What any correct leaderboard satisfies: its columns, R@5 >= R@1 and R@95P >= R@100P (a looser
    condition finds at least as much), every interval around its value, one for each scored row but chance."""
    from greenloop.experiments.leaderboard import rows as leaderboard
    assert list(t.columns) == leaderboard.COLUMNS
    scored = t.dropna(subset=["R@1_%"])
    for c in leaderboard.METRICS + ["pair_AP_%"]:
        assert scored[c].dropna().between(0, 100).all(), c
    assert (scored["R@5_%"] >= scored["R@1_%"]).all() and (scored["R@95P_%"] >= scored["R@100P_%"]).all()
    m = scored.dropna(subset=["R@1_lo_%"])                       # every scored row but chance has its interval
    assert len(m) == len(scored) - len(t[t.method.str.startswith("chance")])
    for k in ("R@1", "AUC-PR"):
        assert (m[f"{k}_lo_%"] <= m[f"{k}_%"] + 1e-9).all() and (m[f"{k}_%"] <= m[f"{k}_hi_%"] + 1e-9).all(), k


def _check_13_counts(folder, t):
    """Every row says the queries it rests on (one count per mode, the dictionary's and chance's the
    methods'), the step the notebook chose from the requested 4 is 1, and the revisit count it chose
    by is the table's; threshold_carry and targets carry the same loop-closure counts."""
    from greenloop.experiments.leaderboard import rows as leaderboard
    assert t[leaderboard.COUNTS].notna().all().all() and (t.revisit_queries <= t.queries).all()
    per_mode = t.groupby("mode")[leaderboard.COUNTS].nunique()
    assert (per_mode == 1).all().all(), per_mode
    lc = t[t["mode"] == "loop closure"].iloc[0]
    assert lc.revisit_queries > 0
    man, s = (json.loads((folder / f).read_text()) for f in ("manifest.json", "summary.json"))
    man = man["parameters"]
    assert man["frame_step"] == s["frame_step"] == 1 and man["frame_step_requested"] == s["frame_step_requested"] == 4
    rule = man["frame_step_rule"]
    assert rule == s["frame_step_rule"] and rule.startswith("frame_step 1, not the requested 4")
    assert f"step 1: {lc.revisit_queries})" in rule, rule
    carry = pd.read_csv(folder / "threshold_carry.csv")
    assert (carry[leaderboard.COUNTS] == lc[leaderboard.COUNTS].astype(int).tolist()).all().all()
    # false_closures holds, per configuration, exactly the false closures threshold_carry counts at the fixed threshold
    false = pd.read_csv(folder / "false_closures.csv")
    assert "distance_m" in false.columns or not len(false)        # the tiny sequence has poses
    for _, r in carry[carry.protocol == "leaderboard"].iterrows():
        wrong = round(r.declared_at_fixed * (1 - r["precision_at_fixed_%"] / 100)) if r.declared_at_fixed else 0
        mine = false[(false.protocol == "leaderboard") & (false.configuration == r.configuration)]
        assert mine.closures.sum() == wrong, (r.configuration, mine, wrong)
        assert (mine.first_query <= mine.last_query).all() and (mine.with_partner <= mine.closures).all()
    targets = pd.read_csv(folder / "targets.csv")
    counted = targets[targets.protocol == "leaderboard"].dropna(subset=["queries"])
    assert len(counted) and (counted.queries == lc.queries).all()


def _check_13_comparisons(folder, lc):
    """comparisons.csv: greenloop-seq against every other scored loop-closure row, each metric once, the
    difference the rows' (to rounding), resolved exactly where the written interval excludes 0, on the
    rows' queries; the Markdown beside it."""
    from greenloop.experiments.leaderboard import rows as leaderboard
    c = pd.read_csv(folder / "comparisons.csv")
    assert list(c.columns) == ["protocol"] + leaderboard.COMPARISON_COLUMNS and (folder / "comparisons.md").is_file()
    c = c[(c.protocol == "leaderboard") & (c.a == "greenloop-seq")]
    scored = set(lc.dropna(subset=["R@1_%"]).index) - {"greenloop-seq", "chance (random scores)"}
    assert set(c.b) == scored and len(c) == len(scored) * len(leaderboard.COMPARED)
    assert (c.resolved == ((c.lo > 0) | (c.hi < 0))).all() and (c.lo <= c.hi).all()
    assert (c.queries == lc.loc["greenloop-seq", "queries"]).all()
    for _, r in c.iterrows():
        want = lc.loc[r.a, f"{r.metric}_%"] - lc.loc[r.b, f"{r.metric}_%"]
        assert abs(r.difference - want) <= 0.011, (r.b, r.metric, r.difference, want)


def _check_13_short(folder):
    """short_recordings.csv (the tiny sequence's cuts, greenloop.short_recordings): every cut with both
    named configurations, verified and not, counts that add up, and its targets beside it."""
    from greenloop import short_recordings
    short, targets = pd.read_csv(folder / "short_recordings.csv"), pd.read_csv(folder / "short_targets.csv")
    assert {"revisit", "no-revisit"} <= set(short.kind) and len(short) == 4 * short.cut.nunique() == len(targets)
    assert set(short.configuration) == set(short_recordings.CONFIGURATIONS) and set(short.verify) == {True, False}
    assert (short.right + short.wrong == short.closures).all() and (short.found <= short.revisits).all()
    assert (targets.silent.dropna() == (short.closures[targets.silent.notna()] == 0)).all()


def _check_13(folder):
    from greenloop.experiments.leaderboard import rows as leaderboard
    csv = folder / "leaderboard.csv"
    assert (folder.parent / "leaderboard.csv").read_bytes() == csv.read_bytes()      # the copy is the same bytes
    t = pd.read_csv(csv)
    assert list(t.columns) == leaderboard.COLUMNS
    assert set(t["mode"]) == {"loop closure"} | ({"place recognition"} if TINY.get("reference_frames") else set())
    lc = t[t["mode"] == "loop closure"].set_index("method")
    single = [f"{s} (single frame)" for s in TINY["cnn_backbones"] + [TINY["random_control"], "sift_bovw", "pixels"]]
    seq = ["greenloop-seq", "greenloop-seq-fast", "SeqSLAM (published)", "SeqSLAM (tuned)"]
    assert set(single + seq + ["chance (random scores)"]) <= set(lc.index) and lc.index.str.contains("dictionary").sum() == 1
    _leaderboard_bounds(t)
    # chance sits below greenloop-seq (the tiny sequence's revisit is found far above chance)
    ch = lc.loc["chance (random scores)"]
    for n in ("greenloop-seq", "SeqSLAM (published)"):
        assert lc.loc[n, "R@1_%"] > ch["R@1_%"] + 20 and lc.loc[n, "AUC-PR_%"] > ch["AUC-PR_%"], n
    timed = lc.drop(index="chance (random scores)")
    assert (timed.fps_min > 0).all() and (timed.fps_min <= timed.fps_median).all() and (timed.fps_median <= timed.fps_max).all()
    assert timed.decode_ms.nunique() == 1 and (timed.decode_ms > 0).all() and pd.isna(ch["fps_median"])
    assert lc.loc["SeqSLAM (published)", "bytes_per_stored_frame"] == 64 * 32 * 4 + 4 * 11
    assert lc.loc["pixels (single frame)", "bytes_per_stored_frame"] == 32 * 32 * 4 + 4
    assert "ds 10, R_window 10" in lc.loc["SeqSLAM (published)", "knobs"]
    decided = t.dropna(subset=["closures_declared"])           # every loop-closure row but chance
    assert len(decided) == len(lc) - 1 and (decided["mode"] == "loop closure").all()
    assert (decided.closures_false <= decided.closures_declared).all()
    if TINY.get("reference_frames"):                             # every scored method in both modes
        pr = t[t["mode"] == "place recognition"].set_index("method")
        assert set(pr.index) == set(lc.dropna(subset=["R@1_%"]).index) and pr["pair_AP_%"].isna().all()
        assert pr.loc["greenloop-seq", "R@1_%"] > pr.loc["chance (random scores)", "R@1_%"]
    assert t.scored_on.str.startswith("evaluation queries").all()
    _check_13_counts(folder, t)
    _check_13_comparisons(folder, lc)
    _check_13_short(folder)
    s = json.loads((folder / "summary.json").read_text())
    start = s["timing_window"][0]
    assert start > 0 and s["dictionary_trained_on_frames"] < 200                  # trained before the evaluation part
    for n in ("greenloop-seq", "SeqSLAM (published)"):                          # the check over the revisit
        assert s["stream_matches_matrix"][n]["equal"] and s["stream_matches_matrix"][n]["correct_events"] > 0
    cnn = lc.loc[seqmatch.CNN_NAME]                  # the named CNN configuration: ImageNet weights even in a tiny run
    assert cnn["weights"] == "imagenet" and cnn["knobs"].startswith(seqmatch.CNN_KNOBS["descriptor"] + ",")
    assert s["stream_matches_matrix"][seqmatch.CNN_NAME]["equal"]
    tuning = pd.read_csv(folder / "tuning.csv")
    cw = len(TINY["contrast_windows"])
    assert (tuning.descriptor == "seqslam").sum() == len(TINY["seq_lens"]) * cw
    assert tuning[tuning.seq_len > 1].descriptor.isin(TINY["seq_descriptors"] + ["seqslam"]).all()
    assert (tuning[(tuning.seq_len == 1)].groupby("descriptor").size() % cw == 0).all()
    assert tuning[tuning.descriptor == TINY["cnn_backbones"][0]].whitening.nunique() >= 2   # whitening offered to the CNN


CHECKS = {"01_spot_grouping": _check_01, "02_training_over_seeds": _check_02,
          "03_confusion_matrix": _check_03, "04_shift_robustness": _check_04,
          "05_dictionary_threshold": _check_05, "06_speed": _check_06,
          "07_feature_baselines": _check_07, "08_descriptor_postprocessing": _check_08,
          "09_rgbd_features": _check_09, "10_siamese_rgbd": _check_10, "11_lsh_matching": _check_11,
          "13_leaderboard": _check_13}
CHECKS["12_revisit_protocol"] = _check_12


def test_the_speed_check_fails_on_rates_not_from_the_median_window(tmp_path):
    """_check_06 on a hand-made folder: 70 frames in a median 0.035 s window (p95 0.07 s) are
    2000 frames/s and 0.5 ms per frame; frames/s taken from the p95 window (1000) must fail."""
    def folder(fps):
        (tmp_path / "manifest.json").write_text(json.dumps({"parameters": {"window": 70}}))
        (tmp_path / "summary.json").write_text(json.dumps({
            "window_frames": 70, "median_window_s": 0.035, "p95_window_s": 0.07, "frames_per_s": fps,
            "median_ms_per_frame": 0.5, "p95_ms_per_frame": 1.0, "repeats": TINY["repeats"]}))
        pd.DataFrame({"quantity": ["frames per second"], "paper": [920], "this run": [f"{fps:.0f}"]}).to_csv(
            tmp_path / "paper_vs_run.csv", index=False)
        return tmp_path
    _check_06(folder(2000.0))
    with pytest.raises(AssertionError):
        _check_06(folder(1000.0))


def _check_00_pairs(folder):
    from greenloop import groundtruth
    from greenloop.datasets import sequence
    row = pd.read_csv(folder / "dataset.csv").iloc[0]
    assert row.ground_truth == "pairs" and pd.isna(row.path_m)
    dataset = json.loads((folder / "manifest.json").read_text())["dataset"]
    gt = groundtruth.for_sequence(dataset, exclude=TINY["exclude"])
    assert row.loop_pairs == len(groundtruth.loop_pairs(gt)) > 0
    assert (folder / "groundtruth.png").is_file() and not (folder / "trajectory_groundtruth.png").is_file()
    assert sequence.GROUND_TRUTH_NAME in (folder / "dataset.md").read_text()


def _check_03_pairs(folder):
    _check_03(folder)
    e = pd.read_csv(folder / "errors_per_seed.csv")
    assert e.errors_on_same_place_other_time.notna().all()      # the pair ground truth is used


def _check_09_pairs(folder):
    t = pd.read_csv(folder / "rgbd.csv")
    assert t.status.str.startswith("skipped").all() and not any(c.startswith("AP_") for c in t.columns)
    d = pd.read_csv(folder / "paper_vs_run.csv")
    assert (d["this run"] == "skipped").all()


def _check_10_without_depth(folder):
    """Without depth/ notebook 10 skips the fusions and still writes its tables and figures."""
    parameters = json.loads((folder / "manifest.json").read_text())["parameters"]
    seeds = parameters["ranking_seeds"]                     # the supervisions' seeds
    assert parameters["has_depth"] is False
    assert (folder / "figure8_supervisions.png").is_file() and (folder / "figure9_skipped.png").is_file()
    assert pd.read_csv(folder / "fusions.csv").status.str.startswith("skipped").all()
    assert (pd.read_csv(folder / "table2_mid_level_layers.csv")["this run"] == "skipped").all()
    sup = pd.read_csv(folder / "supervisions_per_seed.csv")
    assert sup[sup.train_pairs > 0].supervision.tolist() == [x for x in ("softmax", "contrastive", "multitask")
                                                             for _ in seeds]
    assert sup["AP_%"].between(0, 100).all()
    assert json.loads((folder / "summary.json").read_text())["networks_trained"] == 3 * len(seeds)


PAIR_CHECKS = {"00_dataset": _check_00_pairs, "03_confusion_matrix": _check_03_pairs,
               "07_feature_baselines": _check_07_pairs,
               "09_rgbd_features": _check_09_pairs}


@pytest.fixture(scope="module")
def end_loop_results(tmp_path_factory, shared_cache):
    return _results_folder(tmp_path_factory, shared_cache, "results-end-loop")


@pytest.mark.notebook
@pytest.mark.parametrize("notebook", _on("end_loop"), ids=[p.stem for p in _on("end_loop")])
def test_notebook_runs_on_a_sequence_whose_only_revisit_is_at_its_end(notebook, tiny_end_loop_sequence,
                                                                     end_loop_results, monkeypatch):
    """A user's jpg sequence (no poses, no depth) with one loop closing in its last 20 frames: each
    notebook either splits those revisits into a tuning and an evaluation part or says that no
    honest split exists, and renders the rest either way."""
    folder = _run(notebook, tiny_end_loop_sequence, end_loop_results, monkeypatch, END_LOOP_PARAMS.get(notebook.stem[:2]))
    assert json.loads((folder / "manifest.json").read_text())["dataset_ground_truth"] == "pairs"
    END_LOOP_CHECKS[notebook.stem[:2]](folder)


def _end_loop_08(folder):
    t = pd.read_csv(folder / "postprocessing.csv")
    assert set(t.backbone) == set(END_LOOP_PARAMS["08"]["backbones"]) - {"spot_cnn"}       # 08 skips spot_cnn
    assert "AP_eval_%" in t.columns            # 20 revisit frames, gap 5: an honest split exists
    assert t.filter(like="AP_").stack().dropna().between(0, 100).all()


def _end_loop_12(folder):
    s = json.loads((folder / "summary.json").read_text())
    assert s["first_traversal_end"] == 180 and s["revisit_frames"] == 20   # the fixture's one loop


def _end_loop_13(folder):
    t = pd.read_csv(folder / "leaderboard.csv")
    assert len(t) and t.filter(like="AP").stack().dropna().between(0, 100).all()
    assert json.loads((folder / "manifest.json").read_text())["parameters"]["frame_step"] == 1   # 20 revisit frames
    assert (t.revisit_queries <= t.queries).all() and (t.revisit_queries > 0).all()
    _leaderboard_bounds(t)


def _end_loop_10(folder):
    """The end-loop sequence has no depth/ either: notebook 10 skips the fusions there (and splits)."""
    _check_10_without_depth(folder)


END_LOOP_CHECKS = {"08": _end_loop_08, "10": _end_loop_10, "12": _end_loop_12, "13": _end_loop_13}
# The runs on the other sequences check what those sequences change (the split, the exclusion, the missing
# poses and depth), not the spread over seeds or every backbone (the tiny run checks those): one seed where
# a notebook trains its spot CNN over seeds, and 08 on one network beside the descriptors without one.
ONE_SEED = {"03": {"seeds": [0]}, "05": {"seeds": [0]}, "12": {"seeds": [0]}}
# 10's end-loop run checks the skipped fusions and the split: one seed of each supervision; 13's checks the
# split and the board's bounds: no Siamese row (10 trains that network; 13's tiny run has its row)
END_LOOP_PARAMS = {"10": dict(TINY, ranking_seeds=[0], siamese_seeds=[0]),
                   "08": dict(TINY, backbones=["mobilenetv3small", "sift_bovw", "pixels"]),
                   "12": dict(TINY, **ONE_SEED["12"]), "13": dict(TINY, siamese_rows=[])}


@pytest.fixture(scope="module")
def near_loop_results(tmp_path_factory, shared_cache):
    return _results_folder(tmp_path_factory, shared_cache, "results-near-loop")


@pytest.mark.notebook
@pytest.mark.parametrize("notebook", _on("near_loop"), ids=[p.stem for p in _on("near_loop")])
def test_notebook_runs_on_a_sequence_whose_loops_lie_inside_the_default_window(
        notebook, tiny_near_loop_sequence, near_loop_results, monkeypatch, capsys):
    """A user's sequence: revisits 100 frames apart, inside the default 150-frame window,
    and no PARAMS for exclude; two traversals/ folders, ground truth by frame index from its
    sequence.yaml. As make does, greenloop.study.params prints (once per results folder) the
    exclusion greenloop.exclusion derives and why, and passes exclude = 49 (half the
    closest revisit) before the notebook's parameters (TINY without its exclude); the notebook
    runs to the end on it."""
    from greenloop.study import params
    tmp = near_loop_results / f".tmp-{notebook.stem}.ipynb"
    first = not (near_loop_results / params.PARAMS_NAME).exists()
    assert cli_main(["notebook-params", str(notebook), str(tiny_near_loop_sequence), str(near_loop_results), "--out", str(tmp)]) == 0
    printed = capsys.readouterr().out
    if first:
        assert "exclude 49 frames (the longer of the camera's stay and half the closest revisit)" in printed
        assert "revisits 99..101 frames apart" in printed and "the paper's 150 would leave 0 of" in printed
    else:
        assert "exclude 49" not in printed                             # said once per run of make
    assert not tmp.exists()                                            # not skipped: loops count at 49
    implied = yaml.safe_load((near_loop_results / params.PARAMS_NAME).read_text())
    assert implied == {"exclude": 49, "first_traversal_end": 100}
    folder = _run(notebook, tiny_near_loop_sequence, near_loop_results, monkeypatch,
                  parameters={**implied, **{k: v for k, v in TINY.items() if k != "exclude"},
                              **ONE_SEED.get(notebook.stem[:2], {})})
    cells = json.loads((near_loop_results / notebook.name).read_text())["cells"]
    injected = [c for c in cells if "injected-parameters" in c["metadata"].get("tags", [])]
    assert "exclude = 49\n" in "".join(injected[0]["source"])


@pytest.fixture(scope="module")
def no_counted_loop_results(tmp_path_factory, shared_cache):
    return _results_folder(tmp_path_factory, shared_cache, "results-no-counted-loop")


@pytest.mark.notebook
@pytest.mark.parametrize("notebook", _on("no_counted_loop"), ids=[p.stem for p in _on("no_counted_loop")])
def test_notebook_runs_when_no_loop_lies_outside_its_exclusion_window(
        notebook, tiny_near_loop_sequence, no_counted_loop_results, monkeypatch):
    """exclude = 150 on the near-loop sequence (every loop 99-101 frames apart) leaves no counted
    loop; the notebooks make runs anyway (00, 03, 05) say so in their numbers and run to the end."""
    from greenloop import groundtruth
    assert not groundtruth.for_sequence(tiny_near_loop_sequence, exclude=150).any()
    _run(notebook, tiny_near_loop_sequence, no_counted_loop_results, monkeypatch,
         parameters=dict(TINY, exclude=150, **ONE_SEED.get(notebook.stem[:2], {})))


def test_the_relative_accuracy_check_fails_on_a_wrong_rate():
    """AP 20 against a reference AP 10 is R_a = +100 %; +50 % (the rate against the other row) fails."""
    by = pd.DataFrame({"AP_%": [10.0, 20.0], "R_a_%": [0.0, 100.0]}, index=["ref", "other"])
    _assert_relative_accuracy(by, "ref", "AP_%")
    with pytest.raises(AssertionError):
        _assert_relative_accuracy(by.assign(**{"R_a_%": [0.0, 50.0]}), "ref", "AP_%")


# Notebooks 00-06 read as documents that conclude: their last cell shows the conclusion their module
# generates from the tables the run has just written, and no output is a bare path (the return value of
# report.write_table) or an empty table. Wrapped around their checks in every run that checks them.
CONCLUDES = {"00_dataset": "dataset", "01_spot_grouping": "spot_grouping",
             "02_training_over_seeds": "training_over_seeds", "03_confusion_matrix": "confusion_matrix",
             "04_shift_robustness": "shift_robustness", "05_dictionary_threshold": "dictionary_threshold",
             "06_speed": "speed_claim"}


def _check_concludes(folder):
    """The executed notebook beside `folder` (<results>/<stem>.ipynb, where _run writes it): its last code
    cell shows exactly the Markdown its module's conclusion(folder) returns (a heading naming the dataset,
    the verdicts, the sentences), and no code cell shows a PosixPath(...) or an empty DataFrame."""
    import importlib
    nb = json.loads((folder.parent / f"{folder.name}.ipynb").read_text())
    want = importlib.import_module(f"greenloop.experiments.{CONCLUDES[folder.name]}").conclusion(folder)
    last = [c for c in nb["cells"] if c["cell_type"] == "code"][-1]
    shown = "".join("".join(o.get("data", {}).get("text/markdown", "")) for o in last["outputs"])
    assert want.startswith("### Conclusion on ") and shown.strip() == want.strip(), (shown[:300], want[:300])
    plain = ["".join(o.get("data", {}).get("text/plain", "")) for c in nb["cells"] if c["cell_type"] == "code"
             for o in c.get("outputs", [])]
    assert not [p for p in plain if p.startswith("PosixPath(") or p.startswith("Empty DataFrame")], plain


def _concluding(check):
    """`check` (a folder check, or None), then :func:`_check_concludes`."""
    def both(folder):
        if check is not None:
            check(folder)
        _check_concludes(folder)
    return both


for _stem in CONCLUDES:
    CHECKS[_stem] = _concluding(CHECKS.get(_stem))
    if _stem in PAIR_CHECKS:
        PAIR_CHECKS[_stem] = _concluding(PAIR_CHECKS[_stem])


def test_the_conclusion_check_fails_on_a_bare_path_or_a_stale_conclusion(tmp_path):
    """_check_concludes on a hand-made executed notebook: the conclusion shown must be the module's, and
    an output "PosixPath('...')" fails."""
    from greenloop.experiments import shift_robustness
    folder = tmp_path / "04_shift_robustness"
    folder.mkdir()
    (folder / "manifest.json").write_text(json.dumps({"dataset": "data/gardenspoint", "parameters": {}}))
    pd.DataFrame({"seed": [0, 1], "original_test_%": [90, 91], "shift1_all_frames_%": [80, 82],
                  "shift1_test_only_%": [70, 71]}).to_csv(folder / "table3.csv", index=False)

    def notebook(markdown, plain="x"):
        cells = [{"cell_type": "code", "outputs": [{"data": {"text/plain": plain}}]},
                 {"cell_type": "code", "outputs": [{"data": {"text/markdown": markdown}}]}]
        (tmp_path / "04_shift_robustness.ipynb").write_text(json.dumps({"cells": cells}))
        return folder
    _check_concludes(notebook(shift_robustness.conclusion(folder)))
    with pytest.raises(AssertionError):
        _check_concludes(notebook(shift_robustness.conclusion(folder).replace("Gardens Point", "synthetic")))
    with pytest.raises(AssertionError):
        _check_concludes(notebook(shift_robustness.conclusion(folder), "PosixPath('results/x.md')"))


# ------------------------------------------------------- notebooks 07-13 read as documents that conclude
DOCUMENTS = ("07_feature_baselines", "08_descriptor_postprocessing", "09_rgbd_features", "10_siamese_rgbd",
             "11_lsh_matching", "12_revisit_protocol", "13_leaderboard")
EMPTY_CELLS = {"", "nan", "none", "<na>", "nat"}


def _empty_table(output) -> bool:
    """Whether an output cell's HTML or Markdown table has no cell with content (an empty DataFrame, or
    one whose every value is NaN / empty): a reader sees a header and nothing under it."""
    data = output.get("data", {})
    html = "".join(data.get("text/html", ""))
    if "<table" in html:
        cells = re.findall(r"<td[^>]*>(.*?)</td>", html, flags=re.S)
        return all(c.strip().lower() in EMPTY_CELLS for c in cells)
    rows = [r for r in "".join(data.get("text/markdown", "")).splitlines() if r.lstrip().startswith("|")]
    if len(rows) >= 2:
        cells = [c.strip().lower() for r in rows[2:] for c in r.strip().strip("|").split("|")]
        return all(c in EMPTY_CELLS for c in cells)
    return False


def _assert_document(folder):
    """The executed notebook of results folder ``folder`` reads as a document: no output is a bare path
    (``PosixPath(...)``) or an empty table, and its last cell shows the generated conclusion for the
    dataset it ran on (its name, and a verdict word where study.verdict holds a claim the notebook
    concludes on)."""
    from greenloop.study import verdict
    cells = json.loads((folder.parent / f"{folder.name}.ipynb").read_text())["cells"]
    for k, cell in enumerate(c for c in cells if c["cell_type"] == "code"):
        for o in cell.get("outputs", []):
            assert not "".join(o.get("data", {}).get("text/plain", "")).startswith("PosixPath("), (folder.name, k)
            assert not _empty_table(o), (folder.name, k, "".join(cell["source"])[:120])
    last = cells[-1]
    assert last["cell_type"] == "code" and "conclusion(OUT)" in "".join(last["source"]), folder.name
    shown = "".join("".join(o.get("data", {}).get("text/markdown", "")) for o in last["outputs"])
    assert shown.startswith(f"### Conclusion on {verdict.dataset_name(folder.parent)}"), shown[:200]
    if any(c.notebook == folder.name for c in verdict.CLAIMS):
        words = (verdict.HOLDS, verdict.FAILS, verdict.BUDGET, verdict.UNRESOLVED, verdict.UNTESTABLE, verdict.NOT_RUN)
        assert any(f"**{w}" in shown for w in words), shown[:400]
    assert len(shown.split("\n\n")[-1]) > 80, shown          # the sentences generated from the tables follow


def test_an_empty_table_is_told_from_a_table_with_values():
    """_empty_table on planted outputs: an empty DataFrame's HTML and an all-NaN one are empty, one value is not."""
    html = lambda df: {"data": {"text/html": df.to_html(), "text/plain": repr(df)}}
    assert _empty_table(html(pd.DataFrame(columns=["a", "b"])))
    assert _empty_table(html(pd.DataFrame({"a": [np.nan], "b": [None]})))
    assert not _empty_table(html(pd.DataFrame({"a": [np.nan], "b": [1.5]})))
    md = {"data": {"text/markdown": "| a | b |\n|---|---|\n|  |  |\n"}}
    assert _empty_table(md) and not _empty_table({"data": {"text/markdown": "| a | b |\n|---|---|\n| 1 |  |\n"}})


def _and_document(check):
    """``check`` followed by :func:`_assert_document` on the same results folder."""
    def run(folder):
        check(folder)
        _assert_document(folder)
    return run


for _stem in DOCUMENTS:              # every run of these notebooks (tiny, pairs, end loop) must conclude
    CHECKS[_stem] = _and_document(CHECKS.get(_stem, lambda f: None))
    if _stem in PAIR_CHECKS:
        PAIR_CHECKS[_stem] = _and_document(PAIR_CHECKS[_stem])
    if _stem[:2] in END_LOOP_CHECKS:
        END_LOOP_CHECKS[_stem[:2]] = _and_document(END_LOOP_CHECKS[_stem[:2]])
