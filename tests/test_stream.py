"""greenloop.methods.dictionary.stream (Detector, preprocessing, TFLite export) and the `python -m greenloop detect` CLI.
Correctness only; speed is measured by `python -m greenloop bench`."""
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
keras = pytest.importorskip("keras")

from greenloop.methods.dictionary import cnn, dictionary  # noqa: E402
from greenloop.datasets import sequence  # noqa: E402
from greenloop.methods.dictionary.stream import Detector, export_tflite, preprocess  # noqa: E402

from conftest import run_cli

ROOT = Path(__file__).resolve().parents[1]


def _has_tflite():
    try:
        import tensorflow as tf
        return hasattr(tf, "lite") and hasattr(tf.lite, "Interpreter")
    except ImportError:
        return False


@pytest.fixture(scope="module")
def random_model():
    keras.utils.set_random_seed(1)
    return cnn.build(5)


@pytest.fixture(scope="module")
def brightness_model():
    """A hand-made paper CNN whose label is floor(4 * mean brightness) (0..3) of the 32x32 input:
    conv filter 0 passes the pixel through, dense unit 0 averages it, the output layer's lines
    cross at brightness 0.25, 0.5 and 0.75."""
    m = cnn.build(4)
    wc = np.zeros((3, 3, 1, 32), np.float32)
    wc[1, 1, 0, 0] = 1.0
    wd = np.zeros((28800, 68), np.float32)
    wd[0::32, 0] = 1.0 / 900
    wo = np.zeros((68, 4), np.float32)
    wo[0] = [0, 10, 20, 30]
    bo = np.array([0, -2.5, -7.5, -15], np.float32)
    m.get_layer("conv").set_weights([wc, np.zeros(32, np.float32)])
    m.get_layer("dense").set_weights([wd, np.zeros(68, np.float32)])
    m.get_layer("output").set_weights([wo, bo])
    return m


def _frame(level, shape=(61, 97, 3), rng=None):
    """A frame of mean brightness ~level/255 with a little noise."""
    rng = rng or np.random.default_rng(level)
    return np.clip(level + rng.integers(-3, 4, shape), 0, 255).astype(np.uint8)


def _keras_labels(model, frames, color="bgr"):
    X = np.stack([preprocess(f, color=color) for f in frames])[..., None]
    return model.predict(X, verbose=0).argmax(1)


def test_labels_equal_keras_on_odd_sizes(random_model):
    rng = np.random.default_rng(0)
    colour = [rng.integers(0, 256, (61, 97, 3), dtype=np.uint8) for _ in range(12)]
    gray = [rng.integers(0, 256, (61, 97), dtype=np.uint8) for _ in range(6)]
    small = [rng.integers(0, 256, (20, 25, 3), dtype=np.uint8) for _ in range(4)]  # enlarged
    for frames in (colour, gray, small):
        ref = _keras_labels(random_model, frames)
        det = Detector(random_model, 5, backend="numpy")
        assert np.array_equal(det.predict(frames), ref)
        assert [int(Detector(random_model, 5, backend="numpy").predict([f])[0]) for f in frames] == list(ref)
    rgb = [f[:, :, ::-1].copy() for f in colour]
    det = Detector(random_model, 5, backend="numpy", color="rgb")
    assert np.array_equal(det.predict(rgb), _keras_labels(random_model, colour))


def test_keras_backend_is_model_predict(random_model, brightness_model):
    """backend="keras" (the reference, also `greenloop detect --backend keras`) runs model.predict."""
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 256, (61, 97, 3), dtype=np.uint8) for _ in range(8)]
    det = Detector(random_model, 5, backend="keras")
    assert det.backend == "keras"
    assert np.array_equal(det.predict(frames), _keras_labels(random_model, frames))
    det = Detector(brightness_model, 3, backend="keras")
    ref = Detector(brightness_model, 3, backend="numpy")
    stream = [_frame(v) for v in (20, 20, 90, 20, 200, 90, 90, 20)]
    for f in stream:
        assert det.update(f) == ref.update(f)
    assert det.labels == ref.labels and det.events == ref.events and len(det.events) > 0


@pytest.mark.parametrize("ext", ["png", "jpg"])
def test_preprocessing_equals_load_frames(tmp_path, ext):
    rng = np.random.default_rng(3)
    folder = tmp_path / "seq"
    (folder / "rgb").mkdir(parents=True)
    for i, shape in enumerate([(61, 97, 3), (480, 640, 3), (20, 25, 3), (32, 32, 3)]):
        img = cv2.GaussianBlur(rng.integers(0, 256, shape, dtype=np.uint8), (5, 5), 2)
        cv2.imwrite(str(folder / "rgb" / f"{i}.{ext}"), img)
    paths = sequence.list_frames(folder)
    expected = sequence.load_frames(folder)  # mixed native sizes, all resized to 32x32
    assert expected.shape == (len(paths), 32, 32, 1)
    for p, exp in zip(paths, expected):
        bgr = preprocess(cv2.imread(str(p), cv2.IMREAD_COLOR))  # a camera frame: BGR uint8
        assert bgr.dtype == np.float32 and bgr.shape == (32, 32)
        assert np.array_equal(bgr, exp[..., 0])
    same = folder.parent / "same"
    (same / "rgb").mkdir(parents=True)
    for i in range(3):
        cv2.imwrite(str(same / "rgb" / f"{i}.{ext}"), cv2.GaussianBlur(rng.integers(0, 256, (90, 120, 3), dtype=np.uint8), (5, 5), 2))
    X = sequence.load_frames(same)
    ours = np.stack([preprocess(cv2.imread(str(p))) for p in sequence.list_frames(same)])
    assert np.array_equal(ours, X[..., 0])


def test_closure_events_on_crafted_stream(brightness_model):
    levels = [10, 200, 10, 10, 100, 200, 200, 10, 100, 100, 240, 100, 240, 240]
    frames = [_frame(v) for v in levels]
    det = Detector(brightness_model, 3, backend="numpy")
    truth = det.predict(frames)
    assert list(truth) == [int(4 * v / 255) for v in levels]
    events = [e for f in frames if (e := det.update(f)) is not None]
    assert events == dictionary.closure_events(truth, 4, 3)
    assert events == det.events and det.labels == list(truth) and det.frame_index == len(levels)
    assert [(e["frame"], e["spot"]) for e in events] == [(3, 0), (6, 3), (9, 1)]
    assert all(e["count"] == 3 for e in events)
    assert det.dictionary.counts.tolist() == np.bincount(truth, minlength=4).tolist()


def test_threshold_none_counts_but_declares_nothing(brightness_model):
    levels = [10, 200, 10, 10, 100, 200, 200, 10, 100, 100, 240, 100, 240, 240]
    frames = [_frame(v) for v in levels]
    one = Detector(brightness_model, None, backend="numpy")
    assert one.threshold is None and one.dictionary.threshold is None
    truth = one.predict(frames)
    assert all(one.update(f) is None for f in frames)
    win = Detector(brightness_model, None, backend="numpy")
    assert win.update_many(frames[:5]) == [] and win.update_many(frames[5:]) == []
    for det in (one, win):
        assert det.events == [] and det.labels == list(truth) and det.frame_index == len(levels)
        assert det.dictionary.counts.tolist() == np.bincount(truth, minlength=4).tolist()

@pytest.mark.parametrize("splits", [[14], [1, 5, 8], [3, 3, 3, 5], [7, 0, 7]])
def test_windows_equal_one_at_a_time(brightness_model, splits):
    levels = [10, 200, 10, 10, 100, 200, 200, 10, 100, 100, 240, 100, 240, 240]
    frames = [_frame(v, (45 + i, 70, 3)) for i, v in enumerate(levels)]
    one = Detector(brightness_model, 3, backend="numpy")
    ev_one = [e for f in frames if (e := one.update(f)) is not None]
    win = Detector(brightness_model, 3, backend="numpy")
    ev_win, start = [], 0
    for n in splits:
        ev_win += win.update_many(frames[start:start + n])
        start += n
    assert ev_win == ev_one and win.labels == one.labels
    assert win.dictionary.counts.tolist() == one.dictionary.counts.tolist()
    stacked = Detector(brightness_model, 3, backend="numpy")
    assert stacked.update_many(np.stack([_frame(v) for v in levels])) == ev_one


@pytest.mark.skipif(not _has_tflite(), reason="tf.lite is unavailable in this TensorFlow")
def test_tflite_round_trip(tmp_path, random_model, brightness_model):
    rng = np.random.default_rng(5)
    frames = [rng.integers(0, 256, (61, 97, 3), dtype=np.uint8) for _ in range(9)]
    path = export_tflite(random_model, tmp_path / "m.tflite")
    assert path.is_file() and path.stat().st_size > 1_000_000
    det = Detector(path, 5)
    assert det.backend == "tflite" and det.n_classes == 5
    ref = _keras_labels(random_model, frames)
    assert np.array_equal(det.predict(frames), ref)
    assert [int(det.predict([f])[0]) for f in frames] == list(ref)
    mem = Detector(random_model, 5, backend="tflite")
    assert np.array_equal(mem.predict(frames), ref)
    # quantised export loads and classifies the crafted stream like the float model
    q = Detector(export_tflite(brightness_model, tmp_path / "q.tflite", quantize=True), 3)
    levels = [10, 100, 200, 240]
    assert list(q.predict([_frame(v) for v in levels])) == [0, 1, 3, 3]


def test_cli_detect_on_jpg_folder(tmp_path, brightness_model):
    folder = tmp_path / "run"
    folder.mkdir()
    levels = [10] * 4 + [100] * 3 + [10] * 2 + [200] * 5
    for i, v in enumerate(levels):
        cv2.imwrite(str(folder / f"frame{i}.jpg"), _frame(v, (90, 120, 3)))
    model = tmp_path / "m.keras"
    brightness_model.save(model)
    res = run_cli(["detect", folder, "--method", "dictionary", "--model", model, "--threshold", "3", "--window", "5",
                   "--backend", "numpy"], process=True)
    assert res.returncode == 0, res.stderr
    rows = [l.split("\t") for l in res.stdout.splitlines() if l and l[0].isdigit()]
    assert [(int(r[0]), int(r[1]), int(r[2])) for r in rows] == [(2, 0, 3), (6, 1, 3), (11, 3, 3)]
    assert rows[0][3] == "frame2.jpg"
    summary = [l for l in res.stdout.splitlines() if "summary" in l]
    assert summary and "14 frames, 3 closures" in summary[0] and "frames/s" in summary[0]
    helped = run_cli(["--help"])
    assert helped.returncode == 0 and "detect" in helped.stdout
    missing = run_cli(["detect", folder, "--method", "dictionary", "--model", tmp_path / "nope.keras"])
    assert missing.returncode == 2 and "not found" in missing.stderr
    nofolder = run_cli(["detect", tmp_path / "nodir", "--method", "dictionary", "--model", model])
    assert nofolder.returncode == 2 and "does not exist" in nofolder.stderr
    stray = run_cli(["detect", folder, "--model", model])
    assert stray.returncode == 2 and "--method dictionary" in stray.stderr and "needs no model" in stray.stderr


def test_bad_inputs(tmp_path, random_model):
    with pytest.raises(FileNotFoundError, match="not found"):
        Detector(tmp_path / "missing.keras", 3)
    (tmp_path / "model.h5").write_bytes(b"x")
    with pytest.raises(ValueError, match=".keras or .tflite"):
        Detector(tmp_path / "model.h5", 3)
    with pytest.raises(ValueError, match="threshold"):
        Detector(random_model, 0, backend="numpy")
    with pytest.raises(ValueError, match="backend"):
        Detector(random_model, 3, backend="torch")
    det = Detector(random_model, 3, backend="numpy")
    with pytest.raises(ValueError, match="shape"):
        det.update(np.zeros((10, 10, 2), np.uint8))
    with pytest.raises(ValueError, match="shape"):
        det.update(np.zeros(100, np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        det.update(np.zeros((10, 10, 3), np.float32))
    with pytest.raises(ValueError, match="empty"):
        det.update(np.zeros((0, 10, 3), np.uint8))
    with pytest.raises(ValueError, match="use update"):
        det.update_many(np.zeros((48, 64, 3), np.uint8))
    with pytest.raises(ValueError, match="frame 1 of the window"):
        det.update_many([np.zeros((8, 8), np.uint8), np.zeros((8, 8, 4), np.uint8)])
    with pytest.raises(ValueError, match="n_classes"):
        Detector(random_model, 3, n_classes=2, backend="numpy")
    assert det.frame_index == 0 and det.update_many([]) == []
