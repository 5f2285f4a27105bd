"""`python -m greenloop bench --quick` end to end on the tiny sequence: it runs, writes its
files, and the backends it times give Keras's labels. Correctness only; the figures it prints are
not asserted (they depend on the machine and its load)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("keras")

from conftest import HANG_S  # noqa: E402
from greenloop.speed import bench  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def test_bench_quick_writes_figures_and_backends_agree(tiny_sequence, tmp_path):
    out = tmp_path / "bench"
    env = dict(os.environ, PYTHONPATH=str(ROOT), GREENLOOP_CACHE=str(tmp_path / "models"))
    r = subprocess.run([sys.executable, "-m", "greenloop", "bench", "--quick", "--dataset", str(tiny_sequence),
                        "--out", str(out)], capture_output=True, text=True, env=env, timeout=HANG_S)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads((out / "bench.json").read_text())
    assert res["data"]["random_frames"] is False and res["data"]["n_frames"] == 200
    # every window pipeline, the floor and the single-frame paths were timed
    for k in ("reference", "gray_pass_floor", "numpy", "tflite", "tflite-int8"):
        assert res["windows"][k]["n"] > 0 and res["windows"][k]["median_ms"] > 0
    for k in ("reference", "numpy", "tflite"):
        assert res["single"][k]["p99_ms"] >= res["single"][k]["median_ms"] > 0
    for k in ("numpy", "tflite"):
        a = res["agreement"][k]
        assert a["frames"] == 200 and a["same_labels"] == 200
    assert res["training"]["plain"]["epoch_seconds"] and res["training"]["fast"]["epoch_seconds"]
    assert res["accuracy_200_epochs"] is None  # --quick skips the 200-epoch comparison
    table = (out / "bench.md").read_text()
    assert "floor: one cvtColor pass" in table and "labels equal to Keras (tflite)" in table


def test_same_distribution_tells_apart_what_differs():
    rng = np.random.default_rng(0)
    plain = 0.93 + 0.02 * rng.standard_normal(10)
    shifted = bench.same_distribution(plain, plain - 0.3)
    assert shifted["mann_whitney_p"] < 0.001 and shifted["mean_difference_points"] == pytest.approx(-30)
    same = bench.same_distribution(plain, 0.93 + 0.02 * rng.standard_normal(10))
    assert same["mann_whitney_p"] > 0.05


class _FakeKeras:
    """Stands in for a Keras model: 'predicts' class int(frame mean * 10) and records each call's batch."""

    def __init__(self, n_classes=10):
        self.n_classes, self.calls = n_classes, []

    def predict(self, X, batch_size=None, verbose=0):
        X = np.asarray(X)
        self.calls.append((X[:, 0, 0, 0].copy(), batch_size))
        out = np.zeros((len(X), self.n_classes), np.float32)
        out[np.arange(len(X)), (X.reshape(len(X), -1).mean(1) * 10).astype(int)] = 1
        return out

    def predict_on_batch(self, X):
        return self.predict(X, batch_size=len(X))


def test_paper_window_one_batch_then_the_dictionary_loop():
    from greenloop.methods.dictionary.dictionary import LoopDetector

    model, det = _FakeKeras(), LoopDetector(10, 2)
    X = np.repeat(np.array([0.05, 0.35, 0.35, 0.05, 0.35], np.float32)[:, None, None, None], 4, axis=1)
    X = np.repeat(X, 4, axis=2)
    assert bench.paper_window(model, X, det) == [False, False, True, True, True]   # labels 0 3 3 0 3, tau 2
    assert model.calls[0][1] == 5 and det.counts.tolist()[:4] == [2, 0, 0, 3]


def test_paper_claim_times_windows_of_consecutive_frames():
    model = _FakeKeras()
    X = np.broadcast_to((np.arange(100, dtype=np.float32) / 1000)[:, None, None, None], (100, 2, 2, 1))
    res, times = bench.paper_claim(model, X, 10, threshold=None, window=7, repeats=4, warmup=2, seed=3)
    assert len(model.calls) == 6 and len(times) == res["repeats"] == 4
    for first, batch_size in model.calls:
        assert batch_size == 7 and np.allclose(np.diff(first), 0.001)      # 7 consecutive frames, one batch
    starts = [round(c[0][0] * 1000) for c in model.calls]
    assert starts == np.random.default_rng(3).integers(0, 93, size=6).tolist()
    assert res["window_frames"] == 7 and res["median_window_s"] == pytest.approx(float(np.median(times)))
    assert res["frames_per_s"] == pytest.approx(7 / np.median(times))
    assert res["median_ms_per_frame"] == pytest.approx(1e3 * np.median(times) / 7)
    assert res["p95_window_s"] >= res["median_window_s"] and isinstance(res["cpu"], str)
    short, _ = bench.paper_claim(_FakeKeras(), X[:5], 10, threshold=None, window=7, repeats=1, warmup=0)
    assert short["window_frames"] == 5                                    # fewer frames than a window


def test_stream_rows_and_raw_agreement():
    windows = {"reference": {"frames_per_s": 700.4, "median_ms": 100.0}, "numpy": {"frames_per_s": 7004.0, "median_ms": 10.0},
               "tflite": {"frames_per_s": 3502.0, "median_ms": 20.0}, "gray_pass_floor": {"frames_per_s": 70040.0, "median_ms": 1.0}}
    single = {"reference": {"median_ms": 50.12345, "p99_ms": 80.0}, "numpy": {"median_ms": 0.2, "p99_ms": 0.9},
              "tflite": {"median_ms": 0.3, "p99_ms": 1.5}}
    rows = bench.stream_rows(windows, single, {"numpy": 9, "tflite": 10}, 10)
    assert [r["pipeline"].split(" (")[0].split(":")[0] for r in rows] == ["reference", "greenloop.methods.dictionary.stream",
                                                                           "greenloop.methods.dictionary.stream", "floor"]
    assert [r["window_speed-up"] for r in rows] == [1.0, 10.0, 5.0, 100.0]
    assert [r["window_frames_per_s"] for r in rows] == [700, 7004, 3502, 70040]
    assert [r["labels_equal"] for r in rows] == ["10/10", "9/10", "10/10", ""]
    assert rows[0]["single_median_ms"] == 50.123 and rows[3]["single_p99_ms"] is None

    class _Det:
        def __init__(self, offset):
            self.offset = offset

        def predict(self, frames):                         # raw (n, H, W, 3): class of the mean, shifted for frame 0
            lab = (frames.reshape(len(frames), -1).mean(1) / 255 * 10).astype(int)
            lab[0] += self.offset
            return lab
    X = np.repeat(np.array([0.05, 0.35, 0.55], np.float32), 4).reshape(3, 2, 2, 1)
    raw = [np.full((2, 2, 3), round(255 * v), np.uint8) for v in (0.05, 0.35)]
    assert bench.raw_agreement(_FakeKeras(), {"a": _Det(0), "b": _Det(1)}, raw, X) == {"a": 2, "b": 1}
