"""greenloop.methods: the interface, each registered entry, the registry's readers (the
leaderboard experiment, `detect --method`) and the example of docs/ARCHITECTURE.md."""
import re
import sys
import types
from pathlib import Path

import cv2
import numpy as np
import pytest

from greenloop import features
from greenloop.experiments import leaderboard as experiment
from greenloop.methods import registry
from greenloop.methods.dictionary import entry as dictionary
from greenloop.methods.greenloop_seq import entry as greenloop_seq, seqmatch, seqstream
from greenloop.methods.interface import Data
from greenloop.methods.seqslam import entry as slam_entry, seqslam, seqslam_stream
from greenloop.methods.siamese import entry as scnn
from greenloop.methods.single_frame import cnn_layers, entry as single_frame

ROOT = Path(__file__).resolve().parents[1]
N0, REPEAT, EX, DIM = 80, 40, 20, int(np.prod(seqmatch.CELL_GRID))   # the gradients layout (the default shifts cells)
SCORED = [e for e in registry.ENTRIES if e.score is not None]


@pytest.fixture(scope="module")
def revisit():
    """80 frames of a random walk, then frames 0..39 again with noise; GT +-2 frames."""
    rng = np.random.default_rng(0)
    w = np.cumsum(rng.normal(size=(N0, DIM)), 0).astype(np.float32) * 0.3
    X = np.concatenate([w, w[:REPEAT] + rng.normal(scale=0.3, size=(REPEAT, DIM)).astype(np.float32)])
    n = len(X)
    GT = np.zeros((n, n), bool)
    for k in range(REPEAT):
        GT[max(k - 2, 0):k + 3, N0 + k] = True
    return X, GT | GT.T


def _data(descriptors: dict, GT, tune=None, **params) -> Data:
    p = dict(velocities=(1.0,), seq_lens=[3, 5], contrast_windows=[0, 4], weights=None, whiten_dims=[4])
    n = len(GT)
    return Data("unused", 1, np.arange(n), GT, EX, tune, np.ones(n, bool) if tune is None else ~tune,
                dict(p, **params), dict(descriptors), {}, {})


def test_the_registry_holds_every_family_once_in_leaderboard_order():
    assert list(registry.REGISTRY) == ["single-frame", "cnn-layers", "siamese", "greenloop-seq", "seqslam",
                                       seqmatch.DEFAULT_NAME, seqmatch.CNN_NAME, "dictionary"]
    assert registry.get("seqslam") is slam_entry.ENTRY and registry.REGISTRY["dictionary"].score is None
    with pytest.raises(ValueError, match="registered are"):
        registry.get("nope")


def test_projections_fit_the_given_frames_and_label_the_kept_dim(revisit):
    X, _ = revisit
    fit = np.zeros(len(X), bool)
    fit[:10] = True
    p = single_frame.projections({"cnn": X}, ["cnn"], fit, [4, 64])
    assert list(p["cnn"]) == ["none", "pca 4", "pca 9"]             # 64 clipped to the rank of 10 centred frames
    assert np.allclose(p["cnn"]["pca 4"].mean, seqmatch.fit_projection(X[:10], 4).mean)
    flat = single_frame.projections({"flat": np.ones_like(X)}, ["flat"], fit, [4])   # nothing to whiten
    assert flat == {"flat": {"none": None}}


def test_untuned_records_and_knob_texts(revisit):
    X, GT = revisit
    assert single_frame.untuned(["a"]) == {"a (single frame)": {"descriptor": "a", "whitening": "none", "seq_len": 1,
                                                                "contrast_window": 0}}
    rows, knobs, _ = slam_entry.tune(_data({"seqslam": X}, GT))           # no tuning part: the published row only
    assert rows == [] and knobs == {"SeqSLAM (published)": {"descriptor": "seqslam", "whitening": "none",
                                                            "seq_len": 11, "contrast_window": 10}}
    assert slam_entry.knob_text(knobs["SeqSLAM (published)"]).startswith("64x32 patch-normalised, SAD, ds 10, R_window 10")
    assert greenloop_seq.tune(_data({}, GT, seq_descriptors=["x"])) == ([], {}, {})
    assert "fixed threshold" in greenloop_seq.knob_text(greenloop_seq.named_default())


def test_tuning_picks_each_methods_best_row_on_the_tuning_queries(revisit):
    X, GT = revisit
    tune = np.arange(len(X)) < N0 + 20
    d = _data({"rev": X, "pixels": X[::-1].copy()}, GT, tune, seq_descriptors=["rev", "pixels"], fast_descriptors=["pixels"])
    rows, knobs, best = greenloop_seq.tune(d)
    assert len(rows) == 2 * 2 * 2 and set(knobs) == {"greenloop-seq", "greenloop-seq-fast"}
    top = max(rows, key=lambda r: r["AUC-PR_tune_%"])
    assert best["greenloop-seq"] == top["AUC-PR_tune_%"] and knobs["greenloop-seq"]["descriptor"] == top["descriptor"]
    assert knobs["greenloop-seq-fast"]["descriptor"] == "pixels"
    rows, knobs, best = single_frame.tune_names(d, ["rev"], ["rev"])      # whitening offered, fitted on the tuning frames
    assert {r["whitening"] for r in rows} == {"none", "pca 4"} and list(d.cache["projections"]["rev"]) == ["none", "pca 4"]


def test_a_layer_row_picks_its_networks_best_layer_on_the_tuning_queries(revisit):
    """cnn-layers: one row per network, choosing among its nine layer descriptors (here two carry the
    revisit's signal and the rest are noise) by tuning AUC-PR; without a split, last-avg untuned."""
    X, GT = revisit
    g = cnn_layers.groups({"layer_backbones": ["mobilenetv2", "efficientnetlite0:random"]})
    assert list(g) == ["mobilenetv2, best layer (single frame)", "efficientnetlite0:random, best layer (single frame)"]
    assert g["mobilenetv2, best layer (single frame)"][0] == "mobilenetv2@last-avg" and len(set(g["mobilenetv2, best layer (single frame)"])) == 9
    assert g["efficientnetlite0:random, best layer (single frame)"][0] == "efficientnetlite0@last-avg:random"
    noise = np.random.default_rng(3).normal(size=X.shape).astype(np.float32)
    descs = {s: (X if s == "mobilenetv2@mid-grid2" else noise) for v in g.values() for s in v}
    tune = np.arange(len(X)) < N0 + 20
    rows, knobs, best = cnn_layers.tune(_data(descs, GT, tune, layer_backbones=["mobilenetv2", "efficientnetlite0:random"]))
    assert knobs["mobilenetv2, best layer (single frame)"]["descriptor"] == "mobilenetv2@mid-grid2"
    assert knobs["mobilenetv2, best layer (single frame)"]["seq_len"] == 1 and len(rows) == 18 * 2 * 2
    _, untuned, _ = cnn_layers.tune(_data(descs, GT, None, layer_backbones=["mobilenetv2"]))
    assert untuned["mobilenetv2, best layer (single frame)"]["descriptor"] == "mobilenetv2@last-avg"
    assert cnn_layers.tune(_data({}, GT, tune)) == ([], {}, {}) and cnn_layers.describe(_data({}, GT)) == ({}, {})


def test_entries_score_and_stream_are_the_stage_functions(revisit):
    X, GT = revisit
    d = _data({"cnn": X, "seqslam": X}, GT)
    d.cache["projections"] = single_frame.projections({"cnn": X}, ["cnn"], None, [8])
    single = {"descriptor": "cnn", "whitening": "pca 8", "seq_len": 1, "contrast_window": 4}
    seq = {"descriptor": "cnn", "whitening": "none", "seq_len": 5, "contrast_window": 0}
    slam = {"descriptor": "seqslam", "whitening": "none", "seq_len": 4, "contrast_window": 6}
    S = single_frame.ENTRY.score(single, d)
    assert np.array_equal(S, seqstream.score_matrix(X, EX, 1, (1.0,), 4, d.cache["projections"]["cnn"]["pca 8"]))
    assert np.array_equal(greenloop_seq.score(seq, d), seqstream.score_matrix(X, EX, 5, (1.0,), 0))
    assert np.array_equal(slam_entry.score(slam, d), seqslam_stream.score_matrix(X, EX, 3, 6))
    det = slam_entry.stream(slam, float("nan"), d)
    assert isinstance(det, seqslam_stream.Detector) and det.seq_len == 4 and det.threshold is None
    det = single_frame.ENTRY.stream(single, 0.5, d)
    assert det.threshold == 0.5 and det.projection is d.cache["projections"]["cnn"]["pca 8"]
    for x in X:
        det.update_descriptor(x)
    assert det.bytes_per_frame == 8 * 4 + 4
    assert np.allclose(det.last_scores, S[:len(X) - 1 - EX, -1], atol=1e-5)
    with pytest.raises(ValueError, match="no whitening 'pca 3'"):
        greenloop_seq.score(dict(single, whitening="pca 3"), d)


def test_frame_describers_are_the_streams_descriptors():
    f = np.random.default_rng(1).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    d = _data({}, np.zeros((2, 2), bool))
    assert np.array_equal(slam_entry.describer({}, d)(f), seqslam.describe_frames([f])[0])
    k = {"descriptor": "pixels-patchnorm"}
    assert np.array_equal(greenloop_seq.describer(k, d)(f), seqmatch.describe_frames([f], "pixels-patchnorm")[0])
    assert greenloop_seq.describer({"descriptor": "pixels"}, d)(f).shape == (1024,)


def test_the_named_default_is_untuned_and_keeps_its_fixed_threshold():
    k = greenloop_seq.named_default()
    assert k["descriptor"] == seqmatch.DEFAULT_KNOBS["descriptor"] and k["calibrate"] == seqmatch.DEFAULT_KNOBS["calibrate"]
    X = np.random.default_rng(0).normal(size=(60, int(np.prod(seqmatch.CELL_GRID)))).astype(np.float32)   # gradients-sized
    d = _data({k["descriptor"]: X}, np.zeros((60, 60), bool), np.ones(60, bool))
    assert greenloop_seq.DEFAULT_ENTRY.tune(d) == ([], {seqmatch.DEFAULT_NAME: k}, {})
    direct = seqstream.score_matrix(X, EX, k["seq_len"], tuple(k["velocities"]), 0, None, center_window=k["center_window"],
                                   calibrate=k["calibrate"], repeat_cos=k["repeat_cos"], cell_shift=k["cell_shift"])
    assert k["cell_shift"] == seqmatch.DEFAULT_KNOBS["cell_shift"]
    assert np.array_equal(greenloop_seq.DEFAULT_ENTRY.score(k, d), direct)      # the record's knobs reach the detector
    det = greenloop_seq.DEFAULT_ENTRY.stream(k, k["fixed_threshold"], d)
    assert det.calibrate == k["calibrate"] and det.velocities == tuple(float(v) for v in k["velocities"]) and det.cell_shift == k["cell_shift"]
    assert det.threshold == seqmatch.DEFAULT_THRESHOLD


def _records(entry, X, GT):
    """Every knob record an entry gives (tuned on the first half, and untuned), on X as its descriptor."""
    d = _data({}, GT, np.arange(len(X)) < N0 + 20, seq_descriptors=["pixels"], fast_descriptors=["pixels"],
              cnn_backbones=[], random_control="pixels", layer_backbones=["mobilenetv2"], siamese_rows=["multitask"])
    names = {single_frame.ENTRY.name: "pixels", slam_entry.ENTRY.name: "seqslam",
             seqmatch.DEFAULT_NAME: seqmatch.DEFAULT_KNOBS["descriptor"]}
    d.descriptors.update({names.get(entry.name, "pixels"): X, "sift_bovw": X, scnn.descriptor_name("multitask"): X})
    wide = np.hstack([X, np.tile(X, 2)[:, :seqmatch.SHIFTABLE_DIMS[1] - X.shape[1]]])   # the fused layout's width
    d.descriptors[seqmatch.CNN_KNOBS["descriptor"]] = wide
    d.descriptors.update({s: X for s in cnn_layers.groups(d.params)["mobilenetv2, best layer (single frame)"]})
    return d, entry.tune(d)[1]


def _clear_threshold(S, exclude: int, first: int) -> float:
    """A threshold between two query maxima of S (queries first..N-1) with the widest gap among
    the middle half of them: no score lies near it, so float rounding (a matrix product against a
    stream's matrix-vector products) cannot flip a decision, and some queries but not all fire."""
    m = np.sort([S[:j - exclude, j].max() for j in range(max(first, exclude + 1), len(S))])
    lo, hi = len(m) // 4, max(3 * len(m) // 4, len(m) // 4 + 1)
    k = lo + int(np.argmax(np.diff(m)[lo:hi]))
    return float((m[k] + m[k + 1]) / 2)


@pytest.mark.parametrize("entry", SCORED, ids=[e.name for e in SCORED])
def test_every_registered_stream_declares_what_its_matrix_does(entry, revisit):
    """Stream the revisit through each record's streaming detector at a threshold that fires on
    the revisit and compare its events with the thresholded score matrix (seqstream.stream_check);
    a matrix of another record fails the same check."""
    X, GT = revisit
    d, knobs = _records(entry, X, GT)
    assert knobs
    for name, k in knobs.items():
        S = entry.score(k, d)
        thr = _clear_threshold(S, EX, N0)
        c = seqstream.stream_check(entry.stream(k, thr, d), d.descriptors[k["descriptor"]], S, GT)
        assert c["equal"] and c["events"] > 0 and c["correct_events"] > 0, (name, c)
        shifted = np.roll(S, 7, axis=1)
        assert not seqstream.stream_check(entry.stream(k, thr, d), d.descriptors[k["descriptor"]], shifted, GT)["equal"]


def test_the_cnn_configuration_with_int8_rows_streams_what_its_matrix_declares(revisit):
    """The CNN configuration's record with store_dtype "int8" (rows as int8 and a scale each): its
    matrix compares with the stored int8 values, so the stream declares what the thresholded matrix
    does (stream_check, at a threshold no score lies within float rounding of) and its last column
    is the stream's scores to 1e-4; the float32 record's matrix differs from it."""
    X, GT = revisit
    entry = greenloop_seq.CNN_ENTRY
    d, knobs = _records(entry, X, GT)
    k = dict(knobs[entry.name], store_dtype="int8")
    S = entry.score(k, d)
    assert not np.array_equal(S, entry.score(dict(k, store_dtype="float32"), d))
    det = entry.stream(k, _clear_threshold(S, EX, N0), d)
    assert det.store_dtype == np.int8
    c = seqstream.stream_check(det, d.descriptors[k["descriptor"]], S, GT)
    assert c["equal"] and c["events"] > 0 and c["correct_events"] > 0, c
    assert np.allclose(det.last_scores, S[:len(X) - 1 - EX, -1], atol=1e-4)


def test_detect_takes_the_cnn_configurations_store_from_a_flag(tmp_path):
    """--store-dtype sets the CNN configuration's store_dtype knob (float32 by default, said in the
    header); the named default has no such knob and refuses it, naming the method that takes it."""
    from greenloop import detect
    from conftest import write_frames
    folder = write_frames(tmp_path / "seq", 3)
    knobs, _, _, lines, _ = detect.knobs_for(seqmatch.CNN_NAME, folder, store_dtype=None)
    assert knobs["store_dtype"] == "float32" and f"# store_dtype float32 (default {seqmatch.CNN_NAME})" in lines
    knobs, _, _, lines, _ = detect.knobs_for(seqmatch.CNN_NAME, folder, store_dtype="int8")
    assert knobs["store_dtype"] == "int8" and "# store_dtype int8 (--store-dtype)" in lines
    assert greenloop_seq.CNN_ENTRY.stream(knobs, knobs["fixed_threshold"], _data({}, np.zeros((2, 2), bool))).store_dtype == np.int8
    with pytest.raises(ValueError, match=f"--store-dtype does not apply.*{seqmatch.CNN_NAME}"):
        detect.knobs_for(seqmatch.DEFAULT_NAME, folder, store_dtype="int8")


def _example(monkeypatch):
    """The 'Adding a descriptor' blocks of docs/ARCHITECTURE.md, run: the module block becomes the
    module it names (greenloop.features.hue) and the registry line a line of features.BACKBONES
    (both undone after the test). Returns the module."""
    text = (ROOT / "docs" / "ARCHITECTURE.md").read_text()
    section = text[text.index("## Adding a descriptor"):text.index("## Adding a detector")]
    code, line = re.findall(r"```python\n(.*?)```", section, re.S)[:2]
    assert len([c for c in code.splitlines() if c.strip()]) <= 10 and len(line.strip().splitlines()) == 1
    module = types.ModuleType("greenloop.features.hue")
    exec(compile(code, "ARCHITECTURE.md", "exec"), module.__dict__)
    monkeypatch.setitem(sys.modules, module.__name__, module)
    record = eval(line, {"Backbone": features.Backbone})
    monkeypatch.setitem(features.BACKBONES, record.name, record)
    return module


def _walk_folder(folder: Path) -> Path:
    """40 smooth random colour frames, then frames 0..19 again with noise (rgb/, 60 .png) and
    their loops as ground_truth.csv (i, 40 + i, tolerance 1)."""
    rng = np.random.default_rng(0)
    base = [cv2.GaussianBlur(rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), (9, 9), 3) for _ in range(40)]
    frames = base + [np.clip(f.astype(int) + rng.integers(-4, 5, f.shape), 0, 255).astype(np.uint8) for f in base[:20]]
    (folder / "rgb").mkdir(parents=True)
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / "rgb" / f"{i}.png"), f)
    (folder / "ground_truth.csv").write_text("i,j,tolerance\n" + "".join(f"{i},{40 + i},1\n" for i in range(20)))
    return folder


SIAMESE = dict(siamese_rows=["contrastive"], siamese_input_size=32, siamese_width=0.25, siamese_epochs=2,
               siamese_pairs=40, siamese_batch=20, siamese_seeds=[0], hard_fraction=0.5, augment_shift=0.125,
               augment_light=0.2, frames_per_spot=10)


def test_the_siamese_row_trains_only_before_the_evaluation_part_and_streams_its_descriptors(tmp_path, monkeypatch):
    from greenloop.methods.siamese import siamese
    from greenloop.util import cache

    monkeypatch.setattr(cache, "CACHE_DIR", tmp_path / "models")
    folder = _walk_folder(tmp_path / "walk")
    data, _ = experiment.prepare(folder, 1, 0.5, 10, 0.5, None, dict(seq_lens=[3], fps_frames=5, contrast_windows=[0, 4],
                                                                      velocities=(1.0,), whiten_dims=[4], **SIAMESE))
    train = scnn.training_frames(data)
    assert not (train & siamese.near_heldout(data.evalq, 3)).any() and train[:40].all()
    X, info = scnn.describe(data)
    name = scnn.descriptor_name("contrastive")
    assert list(X) == [name] and X[name].shape == (60, siamese.DESCRIPTOR_DIM) and info[name].dim == 128
    labels = siamese.place_labels(train, data.GT, 10)
    _, hist, pairs = siamese.train(siamese.load_inputs(folder, (32, 32), depth=False), labels, supervision="contrastive",
                                   gt=data.GT, **scnn.train_kw(data.params))
    assert len(hist["loss"]) == 2                      # read back from the cache describe filled
    siamese.check_pairs(pairs["pairs"], data.evalq, 3)
    data.descriptors.update(X)
    rows, knobs, best = scnn.tune(data)
    assert list(knobs) == [f"{name} (single frame)"] and knobs[f"{name} (single frame)"]["seq_len"] == 1 and rows
    frame = cv2.imread(str(folder / "rgb" / "7.png"), cv2.IMREAD_COLOR)
    assert np.allclose(scnn.describer(knobs[f"{name} (single frame)"], data)(frame), X[name][7], atol=1e-5)
    assert scnn.describe(data._replace(tune=None)) == ({}, {})           # no honest split: nothing to train on


def test_the_documented_descriptor_appears_to_the_notebooks_the_leaderboard_and_detect(tmp_path, monkeypatch):
    """One module and one registry line: the notebooks' extract_all takes the name, the leaderboard's
    single-frame matcher gives it a tuned row, and the stream detect runs (single_frame.cli_knobs,
    the entry's stream and describer, speed.timing's step) closes the loops its matrix declares."""
    from greenloop.speed import timing
    from greenloop.util import cache
    hue = _example(monkeypatch)
    monkeypatch.setattr(cache, "CACHE_DIR", tmp_path / "models")
    for name in [n for n in registry.REGISTRY if n != "single-frame"]:          # keep the run to seconds
        monkeypatch.delitem(registry.REGISTRY, name)
    folder = _walk_folder(tmp_path / "walk")
    rgb = np.stack([cv2.imread(str(folder / "rgb" / f"{i}.png"))[..., ::-1] for i in range(60)])
    X = hue.hue_histogram(rgb)
    feats, infos = features.extract_all(folder, ["hue-histogram"])                 # notebooks 07 / 08
    assert np.array_equal(feats["hue-histogram"], X) and infos["hue-histogram"].label == "hue-histogram (none)"
    params = dict(seq_lens=[3], contrast_windows=[0, 4], velocities=[1.0], threshold_rule="f1", fps_frames=5,
                  timing_repeats=3, cnn_backbones=[], random_control="pixels-patchnorm", vocab_size=16, whiten_dims=[4])
    data, split = experiment.prepare(folder, 1, 0.5, 10, 0.5, None, params)
    tuned = experiment.tune(data)
    timed = experiment.stream_and_time(data, tuned, experiment.decide(data))
    board = experiment.board(data, split, tuned, timed).board.set_index("method")
    row = board.loc["hue-histogram (single frame)"]
    assert np.isfinite(row[["R@1_%", "R@5_%", "AUC-PR_%", "R@100P_%", "R@95P_%"]].astype(float)).all()
    assert row["bytes_per_stored_frame"] == 32 * 4 + 4 and row["fps_min"] > 0
    assert (tuned.rows.descriptor == "hue-histogram").sum() == 2                   # its contrast windows, tuned
    S = tuned.S["hue-histogram (single frame)"]
    assert np.array_equal(S, seqstream.score_matrix(X, data.exclude, 1, (1.0,), tuned.knobs[row.name]["contrast_window"]))

    entry, knobs = registry.REGISTRY["single-frame"], single_frame.cli_knobs("hue-histogram")   # detect's path
    det, describe = entry.stream(knobs, 0.99, data), entry.describer(knobs, data)
    step = timing.detector_method("single-frame", det, describe).step
    events = [e for e in (step(det, cv2.imread(str(folder / "rgb" / f"{i}.png"))) for i in range(60)) if e]
    ref = entry.stream(knobs, 0.99, data)
    assert events and events == [e for e in (ref.update_descriptor(x) for x in X) if e]
    with pytest.raises(ValueError, match="valid names: .*hue-histogram"):
        single_frame.cli_knobs("hue-histogam")


def test_the_dictionary_decides_and_has_no_score():
    e = registry.REGISTRY["dictionary"]
    assert e.score is None and e.decide is dictionary.decide and e.tune(None) == ([], {}, {})
    assert dictionary.label(10, 70) == "main paper: CNN + dictionary, tau = L + 10 = 70"



STREAMED = [e for e in registry.ENTRIES if e.score is not None and e.stream is not None and e.cli_knobs is not None]


@pytest.mark.parametrize("entry", STREAMED, ids=[e.name for e in STREAMED])
def test_detect_method_streams_what_the_entrys_matrix_declares(entry, tmp_path, capsys):
    """`detect --method NAME` on a folder: the closures it prints fall on exactly the queries where
    the entry's score matrix of its CLI knobs (on the describer's descriptors of the same frames)
    reaches the threshold."""
    from greenloop.__main__ import main
    folder = _walk_folder(tmp_path / "walk")
    k = entry.cli_knobs
    d = _data({}, np.zeros((60, 60), bool), velocities=seqmatch.DEFAULT_VELOCITIES, weights="auto")._replace(exclude=10)
    describe = entry.describer(k, d)
    X = np.stack([describe(cv2.imread(str(folder / "rgb" / f"{i}.png"))) for i in range(60)])
    d.descriptors[k["descriptor"]] = X
    S = entry.score(k, d)
    thr = _clear_threshold(S, 10, 40)
    expected = seqmatch.matrix_events(S, thr, 10, 60)
    assert main(["detect", str(folder), "--method", entry.name, "--threshold", repr(thr), "--exclude", "10"]) == 0
    out = capsys.readouterr().out
    assert expected and [int(line.split("\t")[0]) for line in out.splitlines() if line[:1].isdigit()] == expected
