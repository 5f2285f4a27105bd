"""greenloop.experiments.default_choice on a small stream the test makes: its ranking reads only tuning
queries, the reversed stream is the revisit driven the other way, the repeat gate counts copies."""
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from greenloop.experiments import default_choice as dc
from greenloop.methods.greenloop_seq import seqmatch

D, N0, REV, EX = int(np.prod(seqmatch.CELL_GRID)), 300, 120, 40     # the gradients layout (cell shifts)


@pytest.fixture(scope="module")
def stream():
    """A route of N0 places (a random walk plus each place's own detail), then a noisy revisit of
    its first REV places; the revisit's first half are the tuning queries."""
    rng = np.random.default_rng(0)
    w = np.cumsum(rng.normal(size=(N0, D)), 0) * 0.3 + rng.normal(size=(N0, D))
    X = np.concatenate([w, w[:REV] + rng.normal(scale=0.8, size=(REV, D))]).astype(np.float32)
    n = len(X)
    GT = np.zeros((n, n), bool)
    for k in range(REV):
        GT[max(k - 2, 0):k + 3, N0 + k] = True
    GT |= GT.T
    tune = np.zeros(n, bool)
    tune[N0:N0 + REV // 2] = True
    return X, GT, EX, tune


def test_reversed_stream_is_the_tuning_revisit_backwards(stream):
    X, GT, ex, tune = stream
    Xr, Gr, exr, q = dc.reversed_stream(stream)
    assert len(Xr) == N0 + REV // 2 and exr == ex and q.sum() == REV // 2 and not q[:N0].any()
    np.testing.assert_array_equal(Xr[N0], X[N0 + REV // 2 - 1])          # the last tuning query comes first
    assert Gr[REV // 2 - 1, N0] and not Gr[0, N0] and Gr[0, -1]          # ...its partner is its place


def test_rank_reads_tuning_queries_only_and_sorts(stream):
    X, GT, ex, tune = stream
    t1 = dc.rank({"s": stream}, grid=[50, [3, 15]], reverse=["s"], shifts=(0, 1))
    broken = GT.copy()
    later = np.arange(len(GT)) >= N0 + REV // 2                        # the revisit's untuned queries
    broken[:, later] = broken[later, :] = False                        # lose their labels
    t2 = dc.rank({"s": (X, broken, ex, tune)}, grid=[50, [3, 15]], reverse=["s"], shifts=(0, 1))
    assert list(t1.columns) == ["center_window", "cell_shift", "AUC-PR_tune_% s", "R@1_tune_% s", "R@1_tune_% s, reversed",
                                "mean_AUC-PR_tune_%"]
    assert sorted(zip(t1.center_window, t1.cell_shift)) == [("50", 0), ("50", 1), ("[3, 15]", 0), ("[3, 15]", 1)]
    np.testing.assert_allclose(t1["AUC-PR_tune_% s"], t2["AUC-PR_tune_% s"])
    assert t1["mean_AUC-PR_tune_%"].is_monotonic_decreasing
    assert (t1["R@1_tune_% s"] > 80).all() and (t1["R@1_tune_% s, reversed"] > 50).all()


def test_repeat_gate_counts_copies(stream):
    X, GT, ex, tune = stream
    Xs = np.concatenate([X[:100], np.repeat(X[100:101], 11, axis=0)])   # a stop: 10 copies of one frame
    g = dc.repeat_gate({"s": (Xs, None, ex, None)}, levels=(0.999,))
    assert g["gated_%_at_0.999"][0] == pytest.approx(100 * 10 / (len(Xs) - 1))
    assert dc.threshold(stream, [3, 15]) == pytest.approx(
        seqmatch.choose_threshold(dc._scores(stream, [3, 15]), GT, ex, tune, rule="p95"))


def test_the_committed_choice_is_the_code_default():
    """The committed table's winner is seqmatch.DEFAULT_KNOBS' center_window and cell_shift and its p95 pick,
    rounded to one decimal, is DEFAULT_THRESHOLD (the CNN configuration's, CNN_THRESHOLD, picked at the
    width the width table ranks first, features.FUSED_WIDTH): a default changed without `make default-choice`
    fails here."""
    folder = Path(__file__).resolve().parents[1] / "results" / "default_choice"
    table = pd.read_csv(folder / "windows.csv")
    params = json.loads((folder / "manifest.json").read_text())["parameters"]
    assert table["center_window"][0] == params["winner"] == str(list(seqmatch.center_windows(seqmatch.DEFAULT_KNOBS["center_window"])))
    assert table["cell_shift"][0] == params["winner_cell_shift"] == seqmatch.DEFAULT_KNOBS["cell_shift"]
    assert round(params["p95_threshold"], 1) == seqmatch.DEFAULT_THRESHOLD
    assert params["cnn_configuration"] == seqmatch.CNN_NAME                 # and the CNN configuration's threshold
    assert round(params["cnn_p95_threshold"], 1) == seqmatch.CNN_THRESHOLD
    assert params["repeat_levels"] and seqmatch.DEFAULT_KNOBS["repeat_cos"] in params["repeat_levels"]
    from greenloop import features
    widths = pd.read_csv(folder / "cnn_width.csv")
    assert widths["cnn_width"][0] == params["cnn_width_winner"] == params["fused_width"] == features.FUSED_WIDTH


@pytest.fixture(scope="module")
def end_loop_stream(tiny_end_loop_sequence):
    """tiny_end_loop_sequence as a stream of its gradients: frames 180..199 revisit 0..19 (+- 1), the
    first ten of them the tuning queries; with its folder and frame numbers (``stream_frames``' form)."""
    from greenloop import features
    n = 200
    G = features.extract(tiny_end_loop_sequence, "gradients", progress=False)
    GT = np.zeros((n, n), bool)
    for k in range(20):
        GT[max(k - 1, 0):k + 2, 180 + k] = True
    GT |= GT.T
    tune = np.zeros(n, bool)
    tune[180:190] = True
    return (G, GT, 20, tune), (str(tiny_end_loop_sequence), np.arange(n))


def test_cnn_part_at_the_configuration_width_is_the_configuration_descriptor(tiny_end_loop_sequence):
    from greenloop import features
    from greenloop.similarity import l2_normalise
    from greenloop.datasets import sequence
    frames = sequence.load_frames(tiny_end_loop_sequence, size=None, gray=False, limit=12, dtype=np.uint8, progress=False)
    X = features.extract(frames, seqmatch.CNN_KNOBS["descriptor"], progress=False)
    G = features.extract(frames, "gradients", progress=False)
    C = dc.cnn_part(frames, features.FUSED_WIDTH)
    np.testing.assert_allclose(np.hstack([l2_normalise(G), l2_normalise(C)]), X, atol=1e-6)
    narrow = dc.cnn_part(frames, 64)
    assert narrow.shape == C.shape and not np.allclose(narrow, C)      # another width is another input


def test_width_table_reads_tuning_queries_only_ranks_and_times_each_width(end_loop_stream):
    (G, GT, ex, tune), frames = end_loop_stream
    from greenloop.datasets import sequence
    timing = {"t": sequence.load_frames(frames[0], size=None, gray=False, limit=3, dtype=np.uint8, progress=False)}
    t1 = dc.width_table({"s": (G, GT, ex, tune)}, {"s": frames}, timing, widths=(96, 64))
    broken = GT.copy()
    broken[:, 190:] = broken[190:, :] = False                            # the untuned revisit loses its labels
    t2 = dc.width_table({"s": (G, broken, ex, tune)}, {"s": frames}, timing, widths=(96, 64))
    assert list(t1.columns) == ["cnn_width", "AUC-PR_tune_% s", "mean_AUC-PR_tune_%", "cnn_ms_per_frame t"]
    assert sorted(t1.cnn_width) == [64, 96] and t1["mean_AUC-PR_tune_%"].is_monotonic_decreasing   # best first
    np.testing.assert_allclose(t1["AUC-PR_tune_% s"], t2["AUC-PR_tune_% s"])
    np.testing.assert_allclose(t1["mean_AUC-PR_tune_%"], t1["AUC-PR_tune_% s"])
    assert (t1["cnn_ms_per_frame t"] > 0).all() and t1["AUC-PR_tune_% s"].between(0, 100).all()


def test_streams_and_stream_frames_name_the_same_frames(tiny_sequence):
    """The synthetic target stream: every 4th frame (notebook 13's step), its descriptors the ones
    seqmatch.describe gives those frames, and stream_frames the same labels and frame numbers."""
    s = dc.streams(synthetic=tiny_sequence)
    f = dc.stream_frames(synthetic=tiny_sequence)
    assert list(s) == list(f) == [dc.SYNTHETIC_STREAM]
    X, GT, ex, tune = s[dc.SYNTHETIC_STREAM]
    folder, frames = f[dc.SYNTHETIC_STREAM]
    np.testing.assert_array_equal(frames, np.arange(0, 200, dc.SYNTHETIC_STEP))
    assert folder == str(tiny_sequence) and X.shape == (len(frames), D) and GT.shape == (len(frames),) * 2
    from greenloop import features
    np.testing.assert_allclose(X[:3], features.extract(str(tiny_sequence), "gradients", progress=False, step=4)[:3])
