"""greenloop.methods.greenloop_seq.seqmatch (the greenloop-seq detector) and `python -m greenloop detect --method greenloop-seq`.
Fast: random descriptors and raw pixels only, no network weights."""
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from greenloop import evaluate, features
from greenloop.datasets import sequence
from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.methods.greenloop_seq.seqstream import Detector

from conftest import run_cli, write_frames

ROOT = Path(__file__).resolve().parents[1]
D, N0, REPEAT, EXCLUDE = 32, 300, 100, 50


def _walk(n, seed, a=0.9):
    """A random walk that forgets (AR(1), correlation length ~10 frames): (n, D) descriptors."""
    rng = np.random.default_rng(seed)
    x = np.zeros((n, D))
    x[0] = rng.normal(size=D)
    for t in range(1, n):
        x[t] = a * x[t - 1] + np.sqrt(1 - a * a) * rng.normal(size=D)
    return x


@pytest.fixture(scope="module")
def revisit():
    """N0 frames, then the first REPEAT frames again with noise; GT: |i - (j - N0)| <= 2."""
    w = _walk(N0, 0)
    X = np.concatenate([w, w[:REPEAT] + np.random.default_rng(1).normal(scale=1.0, size=(REPEAT, D))])
    n = len(X)
    GT = np.zeros((n, n), bool)
    for k in range(REPEAT):
        GT[max(k - 2, 0):k + 3, N0 + k] = True
    return X, GT | GT.T


def _run(X, threshold=0.55, **kw):
    det = Detector(threshold, seq_len=10, exclude=EXCLUDE, contrast_window=0, **kw)
    events = [e for x in X if (e := det.update_descriptor(x)) is not None]
    return det, events


def test_finds_the_synthetic_revisit(revisit):
    X, _ = revisit
    det, events = _run(X)
    assert events == det.events and det.frame_index == len(X)
    assert all(e["frame"] >= N0 for e in events), "a closure before the revisit began"
    right = [e for e in events if abs(e["match"] - (e["frame"] - N0)) <= 3]
    assert len(right) == len(events)                              # no false closure
    assert len(right) >= 0.8 * REPEAT                             # most of the revisit found
    assert min(e["frame"] for e in events) < N0 + 15              # and soon after it starts


def test_silent_without_revisit():
    det, events = _run(_walk(N0 + REPEAT, 5))
    assert events == [] and det.frame_index == N0 + REPEAT


def test_sequence_beats_single_frames(revisit):
    X, GT = revisit
    ap = {L: evaluate.average_precision(seqstream.score_matrix(X, EXCLUDE, L, contrast_window=0), GT, EXCLUDE)
          for L in (1, 10)}
    assert ap[10] > ap[1]


@pytest.mark.parametrize("kw", [dict(contrast_window=10), dict(contrast_window=0, store_dtype="float16"),
                                dict(contrast_window=6, velocities=(1.0,), seq_len=3),
                                dict(contrast_window=0, store_dtype="int8"),
                                dict(contrast_window=0, store_dtype="int8", center_window=[3, 15], calibrate="neighbourhood")])
def test_stream_equals_score_matrix(revisit, kw):
    X, _ = revisit
    X = X[::2]
    opts = {"seq_len": 5, "exclude": 20, **kw}
    S = seqstream.score_matrix(X, **opts)
    det = Detector(None, **opts)
    for j, x in enumerate(X):
        assert det.update_descriptor(x) is None                   # threshold None: scores only
        c = max(j - 20, 0)
        assert np.allclose(det.last_scores, S[:c, j], rtol=1e-4, atol=1e-4)
        assert np.all(S[c:, j] <= S[:, :].max())
    filled = S[evaluate.pair_mask(len(X), 20)]
    assert np.all(S[~evaluate.pair_mask(len(X), 20)] <= filled.min())
    dims = D * len(kw.get("center_window", [0]))
    scale = 4 * (kw.get("store_dtype") == "int8")
    assert det.bytes_per_frame == dims * np.dtype(kw.get("store_dtype", "float32")).itemsize + scale + 4 * opts["seq_len"]


def test_int8_rows_hold_each_row_within_half_a_level_and_its_matrix_uses_them(revisit):
    """quantise_rows: each entry within half its row's level, the largest at +-127, a zero row
    zero; the int8 stream's stored values are stored_values' (so its matrix is not the float32
    one), a preloaded int8 stream scores as the streamed one, and candidate mode refuses int8."""
    X, _ = revisit
    Y = seqmatch.normalise(X[:50])
    Y[3] = 0
    q, scale = seqmatch.quantise_rows(Y)
    assert q.dtype == np.int8 and scale.dtype == np.float32 and scale[3] == 0 and not q[3].any()
    assert np.all(np.abs(q).max(1)[scale > 0] == seqmatch.INT8_LEVELS)
    assert np.all(np.abs(q * scale[:, None] - Y) <= scale[:, None] / 2 + 1e-7)
    assert np.array_equal(seqmatch.stored_values(Y, "int8"), q.astype(np.float32) * scale[:, None])
    opts = dict(seq_len=5, exclude=20, contrast_window=0, center_window=[3, 15])
    S8, S32 = (seqstream.score_matrix(X, store_dtype=t, **opts) for t in ("int8", "float32"))
    assert not np.array_equal(S8, S32) and np.allclose(S8, S32, atol=0.05)
    streamed, preloaded = Detector(None, store_dtype="int8", **opts), Detector(None, store_dtype="int8", **opts)
    for x in X:
        streamed.update_descriptor(x)
    preloaded.preload(X[:-1])
    preloaded.update_descriptor(X[-1])
    assert np.allclose(preloaded.last_scores, streamed.last_scores, atol=1e-5)
    assert np.allclose(streamed.last_scores, S8[:len(X) - 21, -1], atol=1e-4)
    with pytest.raises(ValueError, match="int8.*index=None"):
        Detector(None, store_dtype="int8", index="scan")


def test_projection_and_metrics(revisit):
    X, GT = revisit
    proj = seqmatch.fit_projection(X[:N0], dim=16)
    S = seqstream.score_matrix(X, EXCLUDE, 10, contrast_window=0, projection=proj)
    det = Detector(None, seq_len=10, exclude=EXCLUDE, contrast_window=0, projection=proj)
    for x in X:
        det.update_descriptor(x)
    assert det.bytes_per_frame == 16 * 4 + 40
    tune, ev = evaluate.split_mask(len(X), 0.5, gt=GT, gap=5)
    t = seqmatch.choose_threshold(S, GT, EXCLUDE, queries=tune)
    c = seqmatch.closures(S, GT, t, EXCLUDE, queries=ev)
    assert c["declared"] >= c["correct"] > 0 and c["revisits"] > 0 and 0 < c["recall"] <= 1
    assert c["first_delay"] is not None and c["first_delay"] >= 0
    r95 = evaluate.recall_at_precision(S, GT, 0.95, EXCLUDE, queries=ev)
    assert evaluate.recall_at_100_precision(S, GT, EXCLUDE, queries=ev) <= r95 <= 1
    hi = seqmatch.choose_threshold(S, GT, EXCLUDE, queries=tune, rule="p95")
    p = seqmatch.closures(S, GT, hi, EXCLUDE, queries=tune)["precision"]
    assert p >= 0.95


def test_patch_normalise():
    rng = np.random.default_rng(0)
    g = rng.random((3, 32, 32)).astype(np.float32)
    z = features.patch_normalise(g).reshape(3, 4, 8, 4, 8)
    assert np.allclose(z.mean(axis=(2, 4)), 0, atol=1e-5) and np.allclose(z.std(axis=(2, 4)), 1, atol=1e-3)
    assert np.all(features.patch_normalise(np.ones((1, 16, 16))) == 0)
    with pytest.raises(ValueError, match="multiples"):
        features.patch_normalise(np.zeros((1, 30, 32)))


@pytest.mark.parametrize("descriptor", ["pixels", "pixels-patchnorm", "gradients"])
def test_frames_give_the_descriptors_of_the_folder(tmp_path, descriptor):
    """cv2-decoded (BGR) frames, one at a time or together, give the folder's very descriptors."""
    folder = write_frames(tmp_path / "seq", 6, size=(50, 40))
    ref = seqmatch.describe(folder, descriptor)
    frames = [cv2.imread(str(p), cv2.IMREAD_COLOR) for p in sequence.list_frames(folder)]
    assert np.array_equal(seqmatch.describe_frames(frames, descriptor), ref)
    assert np.array_equal(np.concatenate([seqmatch.describe_frames([f], descriptor) for f in frames]), ref)
    assert not np.array_equal(seqmatch.describe_frames(frames, descriptor, color="rgb"), ref)
    det = Detector(None, descriptor=descriptor, exclude=2, seq_len=2)
    d = features.BACKBONES[descriptor].dim
    assert det.update_many(frames) == [] and det.frame_index == 6 and det.bytes_per_frame == d * 4 + 8


def test_bad_inputs():
    det = Detector(0.5, exclude=2, contrast_window=0)
    assert det.update_many([]) == [] and det.frame_index == 0 and det.bytes_per_frame == 0
    assert seqstream.score_matrix(np.zeros((0, 8))).shape == (0, 0)
    det.update(np.zeros((30, 40, 3), np.uint8))
    with pytest.raises(ValueError, match="started with"):
        det.update(np.zeros((31, 40, 3), np.uint8))
    with pytest.raises(ValueError, match="frame 3 has shape"):
        det.update_many([np.zeros((30, 40, 3), np.uint8)] * 2 + [np.zeros((30, 40), np.uint8)])
    with pytest.raises(ValueError, match="uint8"):
        det.update(np.zeros((30, 40, 3), np.float32))
    with pytest.raises(ValueError, match="dims"):
        d = Detector(None)
        d.update_descriptor(np.ones(8))
        d.update_descriptor(np.ones(9))
    with pytest.raises(ValueError, match="NaN"):
        Detector(None).update_descriptor(np.full(4, np.nan))
    for bad, cw in [(1.5, 0), (-1.01, 0), (float("nan"), 0), (float("inf"), 10), (4.0, 10)]:
        with pytest.raises(ValueError, match="threshold must lie"):
            Detector(bad, contrast_window=cw)
    assert Detector(3.0, contrast_window=10).threshold == 3.0
    with pytest.raises(ValueError, match="descriptor"):
        Detector(0.5, descriptor="sift", contrast_window=0)
    with pytest.raises(ValueError, match="seq_len"):
        Detector(0.5, seq_len=0, contrast_window=0)
    with pytest.raises(ValueError, match="velocities"):
        Detector(0.5, velocities=(0.0,), contrast_window=0)
    with pytest.raises(ValueError, match="precision"):
        evaluate.recall_at_precision(np.zeros((3, 3)), np.eye(3, dtype=bool), 0.0, 0)


def _revisit_folder(folder: Path) -> Path:
    """30 smooth random frames, then frames 0..14 again with a little noise: 45 .png files."""
    rng = np.random.default_rng(0)
    base = [cv2.GaussianBlur(rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), (9, 9), 3) for _ in range(30)]
    folder.mkdir(parents=True)
    frames = base + [np.clip(f.astype(int) + rng.integers(-4, 5, f.shape), 0, 255).astype(np.uint8) for f in base[:15]]
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / f"{i}.png"), f)
    return folder


def test_cli_detect_by_method(tmp_path):
    folder = _revisit_folder(tmp_path / "run")
    cmd = ["detect", str(folder), "--method", "greenloop-seq", "--descriptor", "pixels-patchnorm", "--exclude", "10",
           "--seq-len", "3", "--contrast-window", "0", "--threshold", "0.8", "--window", "7"]
    res = run_cli(cmd, process=True)
    assert res.returncode == 0, res.stderr
    rows = [line.split("\t") for line in res.stdout.splitlines() if line and line[0].isdigit()]
    assert rows and all(int(r[0]) >= 30 and int(r[1]) == int(r[0]) - 30 for r in rows)
    assert len(rows) >= 10 and rows[0][3] == f"{rows[0][0]}.png"
    summary = [line for line in res.stdout.splitlines() if "summary" in line]
    assert summary and f"45 frames, {len(rows)} closures" in summary[0] and "4108 bytes per stored frame" in summary[0]
    bad = run_cli(cmd[:-4] + ["--threshold", "2"])
    assert bad.returncode == 2 and "threshold must lie" in bad.stderr
    # knobs and threshold read from a notebook 13 summary (the tuned variant), streamed at its frame_step
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"frame_step": 1, "exclude_steps": 10, "thresholds": {"greenloop-seq-fast": 0.8},
                                   "knobs": {"greenloop-seq-fast": {"descriptor": "pixels-patchnorm", "seq_len": 3,
                                                                    "contrast_window": 0}}}))
    tuned = run_cli(cmd[:4] + ["--tuned", summary, "--window", "7"])
    assert tuned.returncode == 0, tuned.stderr
    assert [line.split("\t")[:2] for line in tuned.stdout.splitlines() if line[:1].isdigit()] == [r[:2] for r in rows]
    # no flags at all: the named default, its exclusion by the rule make uses (no ground truth, no frame
    # rate: 10 % of 45 frames, at least 20), printed with the rule
    none = run_cli(cmd[:2])
    assert none.returncode == 0, none.stderr
    assert f"{seqmatch.DEFAULT_NAME} (gradients, seq_len 10, exclude 20," in none.stdout, none.stdout
    assert "# exclude 20 (fraction)" in none.stdout and "10% of the 45 frames" in none.stdout
    # greenloop-seq (the tuned family) without --tuned or --threshold: refused, pointing at the named default
    plain = run_cli(cmd[:4])
    assert plain.returncode == 2 and "needs a threshold" in plain.stderr and seqmatch.DEFAULT_NAME in plain.stderr
    wrong = run_cli(cmd[:4] + ["--tuned", summary, "--variant", "greenloop-seq"])
    assert wrong.returncode == 2 and "no variant 'greenloop-seq'" in wrong.stderr
    nomodel = run_cli(["detect", folder, "--method", "dictionary"])
    assert nomodel.returncode == 2 and "--model" in nomodel.stderr and seqmatch.DEFAULT_NAME in nomodel.stderr


def test_tune_knobs_scores_every_combination_on_the_tuning_queries(revisit):
    X, GT = revisit
    tune, _ = evaluate.split_mask(len(X), 0.5, gt=GT, gap=10)
    proj = seqmatch.fit_projection(X[:N0], dim=8)
    rows = seqstream.tune_knobs({"rev": X, "noise": _walk(len(X), 7)}, GT, EXCLUDE, tune, [1, 10], [0, 6],
                               projections={"rev": {"none": None, "pca 8": proj}})
    assert [(r["descriptor"], r["whitening"], r["seq_len"], r["contrast_window"]) for r in rows] == \
        [(d, w, L, c) for d, ws in (("rev", ("none", "pca 8")), ("noise", ("none",)))
         for w in ws for L in (1, 10) for c in (0, 6)]
    S = seqstream.score_matrix(X, EXCLUDE, 10, seqmatch.DEFAULT_VELOCITIES, 0)
    q = evaluate.per_query(S, GT, EXCLUDE, queries=tune, ks=(1,))
    assert rows[2]["AUC-PR_tune_%"] == round(100 * q["AUC-PR"], 2) and rows[2]["R@1_tune_%"] == round(100 * q["R@1"], 2)
    Sp = seqstream.score_matrix(X, EXCLUDE, 1, seqmatch.DEFAULT_VELOCITIES, 6, proj)
    assert rows[5]["AUC-PR_tune_%"] == round(100 * evaluate.per_query(Sp, GT, EXCLUDE, queries=tune, ks=(1,))["AUC-PR"], 2)
    # not the pair AP: on this revisit the two differ
    assert rows[2]["AUC-PR_tune_%"] != round(100 * evaluate.average_precision(S, GT, EXCLUDE, queries=tune), 2)
    by = {(r["descriptor"], r["whitening"], r["seq_len"], r["contrast_window"]): r["AUC-PR_tune_%"] for r in rows}
    assert min(by["rev", "none", 10, 0], by["rev", "none", 1, 0]) > by["noise", "none", 1, 0] + 30   # the revisit vs noise


def test_pick_knobs_takes_the_best_tuning_row_per_variant():
    rows = [{"descriptor": "pixels", "whitening": "none", "seq_len": 5, "contrast_window": 0, "AUC-PR_tune_%": 40.0},
            {"descriptor": "pixels", "whitening": "none", "seq_len": 10, "contrast_window": 10, "AUC-PR_tune_%": 55.0},
            {"descriptor": "pixels", "whitening": "none", "seq_len": 1, "contrast_window": 10, "AUC-PR_tune_%": 30.0},
            {"descriptor": "cnn", "whitening": "pca 8", "seq_len": 5, "contrast_window": 0, "AUC-PR_tune_%": 70.0},
            {"descriptor": "cnn", "whitening": "none", "seq_len": 10, "contrast_window": 0, "AUC-PR_tune_%": 70.0},
            {"descriptor": "patch", "whitening": "none", "seq_len": 5, "contrast_window": 0, "AUC-PR_tune_%": float("nan")}]
    knobs, score = seqmatch.pick_knobs(rows, {"all": ["pixels", "cnn", "patch"], "fast": ["pixels", "patch"],
                                              "single": (["pixels"], [1])})
    assert knobs == {"all": {"descriptor": "cnn", "whitening": "pca 8", "seq_len": 5, "contrast_window": 0},  # first of a tie
                     "fast": {"descriptor": "pixels", "whitening": "none", "seq_len": 10, "contrast_window": 10},
                     "single": {"descriptor": "pixels", "whitening": "none", "seq_len": 1, "contrast_window": 10}}
    assert score == {"all": 70.0, "fast": 55.0, "single": 30.0}
    with pytest.raises(ValueError, match="no tuning row"):
        seqmatch.pick_knobs(rows, {"none": ["patch"]})


def test_matrix_events_thresholds_each_querys_candidates():
    S = np.zeros((5, 5), np.float32)
    S[0, 2] = 0.9           # query 2 (candidate row 0 only, exclude 1): declared
    S[2, 3] = 0.9           # row 2 is no candidate of query 3 (3 - 2 <= exclude)
    S[1, 4] = 0.5           # query 4: declared at 0.5, not above
    assert seqmatch.matrix_events(S, 0.5, 1, 5) == [2, 4]
    assert seqmatch.matrix_events(S, 0.5, 1, 4) == [2]          # a stream of 4 frames never saw query 4
    assert seqmatch.matrix_events(S, 0.95, 1, 5) == []


def test_stream_matches_matrix(revisit):
    X, _ = revisit
    S = seqstream.score_matrix(X, EXCLUDE, 10, contrast_window=0)
    det, events = _run(X, threshold=0.55)
    assert events and seqstream.stream_matches_matrix(det, S)
    det.events.pop()
    assert not seqstream.stream_matches_matrix(det, S)
    with pytest.raises(ValueError, match="no threshold"):
        seqstream.stream_matches_matrix(Detector(None), S)


def test_stream_disagreement_at_the_threshold_itself_is_float_rounding(revisit):
    """A frame whose matrix score is the threshold may fire on one side only (the stream's
    matrix-vector products round differently): reported apart, not a disagreement; a frame
    clear of the threshold still is one."""
    X, _ = revisit
    S = seqstream.score_matrix(X, EXCLUDE, 10, contrast_window=0)
    det, events = _run(X, threshold=0.55)
    j = events[len(events) // 2]["frame"]
    det.threshold = float(S[:j - EXCLUDE, j].max())          # the threshold is frame j's own score
    det.events = [e for e in det.events if e["frame"] != j]  # ... and the stream rounded it below
    batch = set(seqmatch.matrix_events(S, det.threshold, EXCLUDE, det.frame_index))
    det.events = [e for e in det.events if e["frame"] in batch]   # every other frame as the matrix says
    assert seqstream.stream_disagreements(det, S) == ([], [j]) and seqstream.stream_matches_matrix(det, S)
    k = det.events.pop(0)["frame"]                              # a frame clear of the threshold
    assert seqstream.stream_disagreements(det, S) == ([k], [j]) and not seqstream.stream_matches_matrix(det, S)
