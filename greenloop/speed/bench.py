"""Speed benchmark: the paper's pipeline as written vs greenloop.methods.dictionary.stream, in one process.

    python -m greenloop bench [--out results/bench] [--dataset data/synthetic-greenhouse] [--quick]
                              [--accuracy-seeds 10]

Measures, interleaving reference and candidates so that load from other jobs hits both alike:
(a) 70-frame windows from raw uint8 frames: the reference (per-frame cv2 preprocessing, Keras
    ``model.predict`` on the window, the Python ``LoopDetector.update`` loop) vs
    ``Detector.update_many`` (numpy and tflite backends); frames/s and ratio, plus the paper's own
    quantity (classification + dictionary, preprocessing excluded), and a floor: one cvtColor pass
    over the raw bytes, which bounds the ratio any pipeline that converts colour with OpenCV can
    reach on this machine;
(b) single frames, preprocessing included: median and p99 latency, reference (``model.predict`` on
    one frame) vs ``Detector.update``;
(c) training seconds per epoch: plain ``model.fit`` (``greenloop.methods.dictionary.cnn.train(trainer="plain")``) vs
    the fast path ("fast": ``trainer="auto"``, the fused numba trainer on a CPU) and XLA
    ``model.fit`` (``trainer="xla"``), and the test accuracy of each after the same epochs;
(c') the full 200-epoch protocol over seeds, plain vs fast: both accuracy distributions and the
    training wall times (through the model cache; skipped with --quick);
(d) label agreement of every backend with Keras on all frames; and the accuracy change of a
    dynamic-range quantised TFLite export.
Writes ``<out>/bench.json`` (figures, provenance: date, git commit, CPU; versions) and ``<out>/bench.md`` /
``bench.csv`` (measurement | reference | ours | ratio | target | met?).
If the dataset folder is missing, frames are random (said so in bench.json).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from greenloop.methods.dictionary import cnn, spots  # noqa: E402
from greenloop.datasets import recording, sequence  # noqa: E402
from greenloop.methods.dictionary.dictionary import LoopDetector  # noqa: E402
from greenloop.methods.dictionary.stream import Detector, export_tflite, preprocess  # noqa: E402
from greenloop.speed.timing import timed  # noqa: E402
from greenloop import report  # noqa: E402
from greenloop.util.threads import run_chunked  # noqa: E402

WINDOW = 70
FRAMES_PER_SPOT = 60
RAW_SIZE = (640, 480)


def _synthetic(n: int, n_raw: int, seed: int = 0):
    """Random stand-in data: (raw (n_raw, 480, 640, 3) uint8 BGR noise frames for timing,
    X (n, 32, 32, 1) float32 and y (n,) spot labels: each spot a random 32x32 gray template plus
    per-frame noise, so a classifier can learn it)."""
    rng = np.random.default_rng(seed)
    raw = rng.integers(0, 256, (n_raw, RAW_SIZE[1], RAW_SIZE[0], 3), dtype=np.uint8)
    y = spots.group(n, FRAMES_PER_SPOT)
    templates = rng.integers(0, 256, (y.max() + 1, 32, 32)).astype(np.float32)
    u8 = np.clip(templates[y] + rng.normal(0, 40, (n, 32, 32)), 0, 255).astype(np.uint8)
    return raw, u8


def _load(dataset: Path):
    """(raw frames list for timing, u8 (N, 32, 32) preprocessed frames, y (N,), info dict)."""
    n_raw = 2 * WINDOW
    if dataset.is_dir():
        raw = recording.open_frames(dataset)[:n_raw].read()
        u8 = sequence.load_frames(dataset, dtype=np.uint8, progress=False)[..., 0]
        info = {"dataset": str(dataset), "random_frames": False, **sequence.folder_info(dataset)}
    else:
        n = 2260
        raw, u8 = _synthetic(n, n_raw)
        raw = list(raw)
        info = {"dataset": str(dataset), "random_frames": True,
                "note": f"{dataset} missing: timing frames are uniform random 640x480 BGR noise; "
                        f"training/agreement frames are random 32x32 per-spot templates plus noise "
                        f"({n} frames, {FRAMES_PER_SPOT} per spot)"}
    y = spots.group(len(u8), FRAMES_PER_SPOT)
    return raw, u8, y, info


def _stats(ts) -> dict:
    ts = np.asarray(ts) * 1e3
    return {"median_ms": float(np.median(ts)), "p99_ms": float(np.percentile(ts, 99)),
            "mean_ms": float(ts.mean()), "n": int(len(ts))}


def paper_window(model, X, detector) -> list:
    """The paper's own quantity, one window: Keras ``model.predict`` on the preprocessed frames
    X (W, 32, 32, 1) float32 in one batch of W, then the Python dictionary loop
    (``LoopDetector.update`` per predicted label). Returns the W answers of ``update``."""
    labels = model.predict(X, batch_size=len(X), verbose=0).argmax(1)
    return [detector.update(int(c)) for c in labels]


def _reference_window(model, frames, detector) -> list:
    """The paper's pipeline: preprocess each frame, model.predict the window, Python dict loop."""
    return paper_window(model, np.stack([preprocess(f) for f in frames])[..., None], detector)


def paper_claim(model, X, n_classes: int, threshold: int | None, window: int = WINDOW, repeats: int = 200,
                warmup: int = 5, seed: int = 0):
    """The paper's speed claim measured as it states it: classify a window of frames and count
    them (:func:`paper_window`, preprocessing excluded), on windows of consecutive frames.

    X: (N, 32, 32, 1) float32 preprocessed frames; n_classes, threshold: the ``LoopDetector``'s
    (one detector counts across all windows); window: frames per window (fewer when N is
    smaller); repeats: timed windows, after warmup untimed ones; seed: seeds the windows' random
    start frames. Returns (res, times): times (repeats,) seconds per window; res {'window_frames',
    'median_window_s', 'p95_window_s' (s), 'frames_per_s', 'median_ms_per_frame',
    'p95_ms_per_frame' (ms), 'repeats', 'cpu' (this machine's CPU model)}.
    """
    det = LoopDetector(n_classes, threshold)
    starts = np.random.default_rng(seed).integers(0, max(1, len(X) - window), size=warmup + repeats)
    times = []
    for k, s in enumerate(starts):
        batch = X[s:s + window]
        dt = timed(paper_window, model, batch, det)[1]
        if k >= warmup:
            times.append(dt)
    times, n = np.array(times), len(batch)
    res = {"window_frames": n, "median_window_s": float(np.median(times)), "p95_window_s": float(np.percentile(times, 95)),
           "frames_per_s": float(n / np.median(times)), "median_ms_per_frame": float(1e3 * np.median(times) / n),
           "p95_ms_per_frame": float(1e3 * np.percentile(times, 95) / n), "repeats": len(times), "cpu": report.cpu_model()}
    return res, times


def _gray_pass(frames) -> None:
    """The cheapest step every exact pipeline needs: one cv2.cvtColor pass over each raw frame (it
    reads every byte once), split over the detector's preprocessing threads. Its time is a floor
    for a window, so reference / floor bounds the speed-up any backend can reach on this machine."""
    def work(idx):
        for i in idx:
            cv2.cvtColor(frames[i], cv2.COLOR_BGR2GRAY)

    run_chunked(work, len(frames))


def _preprocess_all(frames) -> list:
    return [preprocess(f) for f in frames]


def _reference_frame(model, frame, detector):
    """The paper's pipeline on one raw frame: preprocess, ``model.predict`` it alone, count it."""
    c = model.predict(preprocess(frame)[None, ..., None], batch_size=1, verbose=0).argmax(1)[0]
    return detector.update(int(c))


def bench_windows(model, raw, dets, rounds: int) -> dict:
    """(a) 70-frame windows from raw frames; all pipelines interleaved round by round."""
    n_classes = int(model.output_shape[-1])
    wins = [raw[i:i + WINDOW] for i in range(0, len(raw) - WINDOW + 1, WINDOW)]
    pre = [np.stack([preprocess(f) for f in w])[..., None] for w in wins]
    small = [(X[..., 0] * 255).round().astype(np.uint8) for X in pre]  # already 32x32 gray frames
    times = {"reference": [], "reference_no_preprocessing": [], "preprocessing_only": [], "gray_pass_floor": [],
             **{k: [] for k in dets}, **{f"{k}_preprocessed_input": [] for k in dets}}
    ref_dict = LoopDetector(n_classes, None)  # counts, never fires
    model.predict(pre[0], batch_size=WINDOW, verbose=0)
    for d in dets.values():
        d.update_many(wins[0])
    for r in range(rounds):
        w, X = wins[r % len(wins)], pre[r % len(pre)]
        times["reference"].append(timed(_reference_window, model, w, ref_dict)[1])
        times["reference_no_preprocessing"].append(timed(paper_window, model, X, ref_dict)[1])
        times["preprocessing_only"].append(timed(_preprocess_all, w)[1])
        times["gray_pass_floor"].append(timed(_gray_pass, w)[1])
        for k, d in dets.items():
            times[k].append(timed(d.update_many, w)[1])
        for k, d in dets.items():
            times[f"{k}_preprocessed_input"].append(timed(d.update_many, small[r % len(small)])[1])
    out = {}
    for k, ts in times.items():
        s = _stats(ts)
        s["frames_per_s"] = WINDOW / (s["median_ms"] / 1e3)
        out[k] = s
    return out


def bench_single(model, raw, dets, n_ref: int, n_ours: int) -> dict:
    """(b) one frame at a time, preprocessing included; blocks of each pipeline interleaved."""
    n_classes = int(model.output_shape[-1])
    ref_dict = LoopDetector(n_classes, None)  # counts, never fires
    times = {"reference": [], **{k: [] for k in dets}}
    blocks = 5
    for k, d in dets.items():
        for f in raw[:20]:
            d.update(f)
    model.predict(preprocess(raw[0])[None, ..., None], verbose=0)
    i = 0
    for _ in range(blocks):
        for _ in range(max(1, n_ref // blocks)):
            f = raw[i % len(raw)]; i += 1
            times["reference"].append(timed(_reference_frame, model, f, ref_dict)[1])
        for k, d in dets.items():
            upd = d.update
            for _ in range(max(1, n_ours // blocks)):
                f = raw[i % len(raw)]; i += 1
                times[k].append(timed(upd, f)[1])
    return {k: _stats(v) for k, v in times.items()}


def raw_agreement(model, dets: dict, raw, X) -> dict:
    """How many raw frames each detector labels as Keras does: dets {backend: ``Detector``} fed
    the raw frames raw (list of (H, W, 3) uint8 BGR), Keras ``cnn.predict`` fed X[:len(raw)]
    (the same frames preprocessed, (N, 32, 32, 1) float32). Returns {backend: equal labels}."""
    keras_labels = cnn.predict(model, X[: len(raw)])
    return {b: int((d.predict(np.stack(raw)) == keras_labels).sum()) for b, d in dets.items()}


def stream_rows(windows: dict, single: dict, same: dict, n_frames: int) -> list[dict]:
    """The reference, each streaming backend and the floor side by side (notebook 06's table).

    windows: :func:`bench_windows`' result, single: :func:`bench_single`'s (same backends),
    same: {backend: frames labelled as Keras} (:func:`raw_agreement`) in row order, n_frames: the
    raw frames compared. Returns one dict per pipeline: pipeline, window_frames_per_s (rounded),
    single_median_ms and single_p99_ms (3 decimals; None for the floor), window_speed-up (the
    reference's median window time over the row's, 1 decimal), labels_equal ("k/n").
    """
    ref = windows["reference"]
    rows = [{"pipeline": "reference: cv2 + model.predict + dict loop", "window_frames_per_s": round(ref["frames_per_s"]),
             "single_median_ms": round(single["reference"]["median_ms"], 3), "single_p99_ms": round(single["reference"]["p99_ms"], 3),
             "window_speed-up": 1.0, "labels_equal": f"{n_frames}/{n_frames}"}]
    for b in same:
        rows.append({"pipeline": f"greenloop.methods.dictionary.stream ({b})", "window_frames_per_s": round(windows[b]["frames_per_s"]),
                     "single_median_ms": round(single[b]["median_ms"], 3), "single_p99_ms": round(single[b]["p99_ms"], 3),
                     "window_speed-up": round(ref["median_ms"] / windows[b]["median_ms"], 1),
                     "labels_equal": f"{same[b]}/{n_frames}"})
    fl = windows["gray_pass_floor"]  # one cvtColor pass over the raw bytes: every exact pipeline pays at least this
    rows.append({"pipeline": "floor: one cvtColor pass over the raw frames (threaded)", "window_frames_per_s": round(fl["frames_per_s"]),
                 "single_median_ms": None, "single_p99_ms": None,
                 "window_speed-up": round(ref["median_ms"] / fl["median_ms"], 1), "labels_equal": ""})
    return rows


def bench_training(X, y, seeds, epochs: int) -> dict:
    """(c) seconds per epoch and test accuracy: cnn.train(trainer="plain") (plain model.fit) vs
    trainer="auto" ("fast") vs trainer="xla", interleaved seed by seed (the first trainer rotates)."""
    trainers = {"plain": "plain", "fast": "auto", "xla": "xla"}
    runs = {kind: [] for kind in trainers}
    for i, seed in enumerate(seeds):
        order = list(runs)[i % len(runs):] + list(runs)[:i % len(runs)]  # rotate who goes first
        for kind in order:
            model, h, split = cnn.train(X, y, seed, epochs=epochs, trainer=trainers[kind],
                                        cache=False, progress=True)
            ep = h["epoch_seconds"]
            runs[kind].append({"seed": int(seed), "seconds": h["seconds"], "epoch_seconds": ep,
                               "seconds_per_epoch": float(np.median(ep[1:] or ep)),
                               "test_accuracy": float(h["val_accuracy"][-1]), "model": model,
                               "split": split})
    out = {}
    for kind, rs in runs.items():
        out[kind] = {"seconds_per_epoch": [r["seconds_per_epoch"] for r in rs],
                     "epoch_seconds": [r["epoch_seconds"] for r in rs],
                     "total_seconds": [r["seconds"] for r in rs],
                     "test_accuracy": [r["test_accuracy"] for r in rs], "seeds": [r["seed"] for r in rs],
                     "median_seconds_per_epoch": float(np.median([r["seconds_per_epoch"] for r in rs])),
                     "mean_test_accuracy": float(np.mean([r["test_accuracy"] for r in rs]))}
    out["epochs"] = int(epochs)
    out["n_train_frames"] = int(len(runs["plain"][0]["split"]["train"]))
    out["trainer"] = cnn.resolve_trainer("auto")
    out["note"] = ("seconds_per_epoch: median wall time of epochs 2.. (the first holds XLA or numba "
                   "compilation; total_seconds includes it), validation on the test split included; "
                   "fast = cnn.train(trainer='auto'), xla = model.fit with XLA and one call per epoch")
    return out, runs["fast"][0]


def bench_accuracy(X, y, seeds, epochs: int) -> dict:
    """(c') the full protocol (random 80/20 split, batch 32, Adam 1e-3, ``epochs``) once per seed
    with plain ``model.fit`` and once with the fast path: test accuracy of each, so the two
    distributions over seeds can be compared, and the wall time of each training.

    Runs go through greenloop.methods.dictionary.cnn's model cache: the fast-path models of the notebooks are reused
    and plain models are trained once, then reused. A cached run keeps the wall time recorded when
    it was trained, so these times are not interleaved (the per-epoch rows are).
    Returns {kind: {'seeds', 'test_accuracy', 'training_seconds'}, 'epochs': epochs}.
    """
    out = {"epochs": int(epochs)}
    for kind in ("plain", "fast"):
        runs = cnn.run_seeds(X, y, seeds, epochs=epochs, trainer={"plain": "plain", "fast": "auto"}[kind])
        out[kind] = {"seeds": [r["seed"] for r in runs],
                     "test_accuracy": [r["test_accuracy"] for r in runs],
                     "training_seconds": [float(r["history"]["seconds"]) for r in runs]}
    return out


def same_distribution(plain, fast) -> dict:
    """Compare two samples of test accuracies (fractions, one per seed): the mean difference
    fast - plain in percentage points and the two-sided Mann-Whitney U test's p-value (no
    normality assumed). A large p says the seeds show no difference, not that there is none;
    below 4 seeds a side the test cannot reach p < 0.05 at all."""
    from scipy.stats import mannwhitneyu

    plain, fast = np.asarray(plain, float), np.asarray(fast, float)
    return {"mean_difference_points": float(100 * (fast.mean() - plain.mean())),
            "mann_whitney_p": float(mannwhitneyu(fast, plain, alternative="two-sided").pvalue)}


def run(out="results/bench", dataset="data/synthetic-greenhouse", quick: bool = False, accuracy_seeds: int = 10) -> str:
    """Time the reference and greenloop.methods.dictionary.stream, train both ways, write
    bench.json / .md / .csv to ``out``. dataset: a sequence folder (random frames if missing);
    quick: fewer repetitions, 1 seed, 2 epochs; accuracy_seeds: seeds of the 200-epoch accuracy
    comparison, plain vs fast (0 skips it). Returns one line saying what was written."""
    (result, rows, best), result_wall = timed(_measure, quick, dataset, accuracy_seeds)
    result["wall_seconds"] = result_wall
    _write(Path(out), result, rows)
    return f"[bench] wrote {Path(out) / 'bench.json'} in {result['wall_seconds']:.0f} s; fastest window backend: {best}"


def _measure(quick: bool, dataset, accuracy_seeds: int):
    """Every measurement of :func:`run`: (bench.json's dict, the table's rows, the fastest backend)."""
    raw, u8, y, info = _load(Path(dataset))
    X = (u8.astype(np.float32) / np.float32(255.0))[..., None]
    n_classes = int(y.max() + 1)
    print(f"[bench] {len(u8)} frames, {n_classes} spots, random={info['random_frames']}", flush=True)

    model = _quick_model(X, y, n_classes)
    tmpdir = tempfile.TemporaryDirectory()
    dets = _detectors(model, Path(tmpdir.name))

    print("[bench] (a) windows", flush=True)
    windows = bench_windows(model, raw, dets, rounds=8 if quick else 30)
    print("[bench] (b) single frames", flush=True)
    single = bench_single(model, raw, dets, n_ref=30 if quick else 150, n_ours=500 if quick else 3000)

    print("[bench] (d) label agreement", flush=True)
    agreement = _agreement(model, dets, X, u8)

    print("[bench] (c) training", flush=True)
    seeds = [0] if quick else [0, 1, 2]
    epochs = 2 if quick else 5
    training, fast_run = bench_training(X, y, seeds, epochs)

    accuracy = None
    if not quick and accuracy_seeds > 0:
        print(f"[bench] (c') 200-epoch accuracy over {accuracy_seeds} seeds, plain vs fast", flush=True)
        accuracy = bench_accuracy(X, y, list(range(accuracy_seeds)), 200)
        accuracy["comparison"] = same_distribution(accuracy["plain"]["test_accuracy"],
                                                   accuracy["fast"]["test_accuracy"])

    quant = _quantized_accuracy(quick, fast_run, epochs, X, y, u8, Path(tmpdir.name))
    best = min(("numpy", "tflite"), key=lambda k: windows[k]["median_ms"])
    result = _result(quick, info, n_classes, Detector(model, None).backend, windows, single, training,
                     accuracy, agreement, quant)
    rows = (_window_rows(windows, dets) + _single_rows(single, dets)
            + _training_rows(training, accuracy, seeds, epochs) + _agreement_rows(agreement, quant))
    tmpdir.cleanup()
    return result, rows, best


def _quick_model(X, y, n_classes: int):
    """The paper's CNN after one seeded epoch of ``model.fit`` on X (N, 32, 32, 1) float32, y (N,):
    the timing is architecture-bound, and the agreement check needs only some weights."""
    import keras


    keras.utils.set_random_seed(0)
    model = cnn.build(n_classes, jit_compile=False)
    Y = keras.utils.to_categorical(y, n_classes).astype(np.float32)
    model.fit(X, Y, epochs=1, batch_size=32, verbose=0)
    return model


def _detectors(model, tmpdir: Path) -> dict:
    """The timed pipelines: {'numpy', 'tflite', 'tflite-int8'} -> counting-only ``Detector``
    (threshold None: the dictionary counts, no closure is declared). The int8 export (written
    into ``tmpdir``) has a quarter of the dense layer's bytes to read per frame; its labels may
    differ from Keras, so it is judged by its test-accuracy change instead."""
    return {"numpy": Detector(model, None, backend="numpy"),
            "tflite": Detector(model, None, backend="tflite"),
            "tflite-int8": Detector(export_tflite(model, tmpdir / "int8.tflite", quantize=True), None)}


def _agreement(model, dets: dict, X, u8) -> dict:
    """(d) per backend: how many of the frames u8 (N, 32, 32) uint8 get Keras's label (Keras on
    X (N, 32, 32, 1) float32). Returns {backend: {'frames', 'same_labels', 'fraction'}}."""
    ref_labels = cnn.predict(model, X)
    agreement = {}
    for k, d in dets.items():
        lab = np.concatenate([d.predict(u8[i:i + 512]) for i in range(0, len(u8), 512)])
        agreement[k] = {"frames": int(len(lab)), "same_labels": int((lab == ref_labels).sum()),
                        "fraction": float(np.mean(lab == ref_labels))}
    return agreement


def _quantized_accuracy(quick: bool, fast_run: dict, epochs: int, X, y, u8, tmpdir: Path) -> dict:
    """Test-accuracy change of the dynamic-range quantised TFLite export, on the model's own test
    split: a model trained with the paper's full protocol (seed 0, 200 epochs: the notebooks'
    cached model when it exists, else trained here), or with --quick the short fast-path run.

    X (N, 32, 32, 1) float32, u8 (N, 32, 32) uint8, y (N,). Returns {'test_frames',
    'keras_accuracy', 'tflite_float_accuracy', 'tflite_dynamic_range_accuracy' (fractions),
    'change_points' (percentage points), 'model' (which one)}.
    """
    if quick:
        q_model, q_split, q_desc = fast_run["model"], fast_run["split"], f"fast-path model, seed {fast_run['seed']}, {epochs} epochs"
    else:
        q_model, _, q_split = cnn.train(X, y, 0, epochs=200)
        q_desc = "paper protocol, seed 0, 200 epochs (greenloop.methods.dictionary.cnn cache)"
    test = q_split["test"]
    q = Detector(export_tflite(q_model, tmpdir / "q.tflite", quantize=True), None)
    f = Detector(export_tflite(q_model, tmpdir / "f.tflite"), None)
    acc_q = float(np.mean(q.predict(u8[test]) == y[test]))
    acc_f = float(np.mean(f.predict(u8[test]) == y[test]))
    acc_k = float(np.mean(cnn.predict(q_model, X[test]) == y[test]))
    return {"test_frames": int(len(test)), "keras_accuracy": acc_k, "tflite_float_accuracy": acc_f,
            "tflite_dynamic_range_accuracy": acc_q, "change_points": 100 * (acc_q - acc_k),
            "model": q_desc}


def _result(quick, info, n_classes, default_backend, windows, single, training, accuracy,
            agreement, quant) -> dict:
    """bench.json's content: the figures plus report.provenance() (date, git commit, environment
    hash, CPU model, platform) and the library versions."""
    return {
        **report.provenance(), "versions": report.versions(), "quick": quick, "data": info, "window": WINDOW,
        "n_classes": n_classes, "default_backend": default_backend,
        "windows": windows, "single": single, "training": training, "accuracy_200_epochs": accuracy,
        "agreement": agreement,
        "quantized_tflite": quant,
        "note": "reference and ours are interleaved in one process, so load from other jobs hits "
                "both alike; ratios are the robust figures",
    }


def _row(measure, ref, ours, ratio, target, met) -> dict:
    """One row of bench.md / bench.csv (all cells strings)."""
    return {"measurement": measure, "reference": ref, "ours": ours, "ratio": ratio,
            "target": target, "met?": met}


def _window_rows(windows: dict, dets: dict) -> list[dict]:
    """Rows of (a): windows with and without preprocessing, preprocessing alone, the floor."""
    ref_w = windows["reference"]
    rows = []
    for k in dets:
        r = ref_w["median_ms"] / windows[k]["median_ms"]
        rows.append(_row(f"70-frame window, frames/s, preprocessing included ({k})", f"{ref_w['frames_per_s']:.0f}",
                         f"{windows[k]['frames_per_s']:.0f}", f"{r:.1f}x", ">= 10x", "yes" if r >= 10 else "no"))
    rn = windows["reference_no_preprocessing"]
    for k in ("numpy", "tflite"):
        r = rn["median_ms"] / windows[k]["median_ms"]
        rows.append(_row(f"70-frame window, frames/s: reference without preprocessing (paper's quantity) vs ours with ({k})",
                         f"{rn['frames_per_s']:.0f}", f"{windows[k]['frames_per_s']:.0f}", f"{r:.1f}x", "(info)", ""))
    for k in ("numpy", "tflite"):
        o = windows[f"{k}_preprocessed_input"]
        r = rn["median_ms"] / o["median_ms"]
        rows.append(_row(f"70-frame window of 32x32 gray frames (no resize), frames/s, vs reference without preprocessing ({k})",
                         f"{rn['frames_per_s']:.0f}", f"{o['frames_per_s']:.0f}", f"{r:.1f}x", ">= 10x", "yes" if r >= 10 else "no"))
    rows.append(_row("preprocessing alone (cvtColor + INTER_AREA, 640x480 -> 32x32), ms/frame", "",
                     f"{windows['preprocessing_only']['median_ms'] / WINDOW:.3f}", "", "(info)", ""))
    fl = windows["gray_pass_floor"]
    rows.append(_row("floor: one cvtColor pass over the window's raw bytes (threaded), frames/s; ratio = the most a "
                     "pipeline converting colour with OpenCV can reach", f"{ref_w['frames_per_s']:.0f}", f"{fl['frames_per_s']:.0f}",
                     f"{ref_w['median_ms'] / fl['median_ms']:.1f}x", "(info)", ""))
    return rows


def _single_rows(single: dict, dets: dict) -> list[dict]:
    """Rows of (b): single-frame median and p99 latency per backend."""
    rows = []
    for k in dets:
        s, sr = single[k], single["reference"]
        rows.append(_row(f"single frame median latency, ms ({k})", f"{sr['median_ms']:.2f}", f"{s['median_ms']:.3f}",
                         f"{sr['median_ms'] / s['median_ms']:.0f}x", "<= 0.3 ms", "yes" if s["median_ms"] <= 0.3 else "no"))
        rows.append(_row(f"single frame p99 latency, ms ({k})", f"{sr['p99_ms']:.2f}", f"{s['p99_ms']:.3f}",
                         f"{sr['p99_ms'] / s['p99_ms']:.0f}x", "<= 1 ms", "yes" if s["p99_ms"] <= 1 else "no"))
    return rows


def _training_rows(training: dict, accuracy: dict | None, seeds, epochs: int) -> list[dict]:
    """Rows of (c) and (c'): seconds per epoch of each trainer, test accuracy after ``epochs``, and
    (when run) the 200-epoch accuracy distributions and training times."""
    tp, tf_ = training["plain"], training["fast"]
    rows = [_row(f"training s/epoch ({training['n_train_frames']} frames, {len(seeds)} seed(s), {epochs} epochs; "
                 f"ours: the {training['trainer']} trainer)",
                 f"{tp['median_seconds_per_epoch']:.2f}", f"{tf_['median_seconds_per_epoch']:.2f}",
                 f"{tp['median_seconds_per_epoch'] / tf_['median_seconds_per_epoch']:.1f}x", ">= 2x",
                 "yes" if tp['median_seconds_per_epoch'] >= 2 * tf_['median_seconds_per_epoch'] else "no")]
    tx = training["xla"]
    rows.append(_row("training s/epoch, XLA model.fit (the fast path where Keras has a GPU) vs plain",
                     f"{tp['median_seconds_per_epoch']:.2f}", f"{tx['median_seconds_per_epoch']:.2f}",
                     f"{tp['median_seconds_per_epoch'] / tx['median_seconds_per_epoch']:.1f}x", "(info)", ""))
    rows.append(_row(f"test accuracy after {epochs} epochs (mean over seeds)", f"{tp['mean_test_accuracy']:.3f}",
                     f"{tf_['mean_test_accuracy']:.3f}", "", "same distribution", ""))
    if accuracy is not None:
        ap_, af = accuracy["plain"], accuracy["fast"]
        fmt = lambda v: f"{100 * np.mean(v):.1f} ± {100 * np.std(v):.1f} % [{', '.join(f'{100 * a:.1f}' for a in v)}]"  # noqa: E731
        same = accuracy["comparison"]
        rows.append(_row(f"test accuracy after 200 epochs, mean ± sd [per seed], seeds {ap_['seeds']}; ratio column: "
                         f"mean difference and two-sided Mann-Whitney p", fmt(ap_["test_accuracy"]), fmt(af["test_accuracy"]),
                         f"{same['mean_difference_points']:+.1f} pt, p = {same['mann_whitney_p']:.2f}", "same distribution",
                         "too few seeds to judge" if min(len(ap_["seeds"]), len(af["seeds"])) < 4
                         else "no difference detected" if same["mann_whitney_p"] >= 0.05 else "no: differs"))
        tp2, tf2 = np.median(ap_["training_seconds"]), np.median(af["training_seconds"])
        # not judged: each time was recorded when its model was trained (another hour, other load);
        # the interleaved s/epoch row is
        rows.append(_row("one 200-epoch training, s (median over seeds; recorded when each was trained, NOT interleaved)",
                         f"{tp2:.0f}", f"{tf2:.0f}", f"{tp2 / tf2:.1f}x", "(info)", ""))
    return rows


def _agreement_rows(agreement: dict, quant: dict) -> list[dict]:
    """Rows of (d): labels equal to Keras per backend, and the quantised export's accuracy change."""
    rows = []
    for k in ("numpy", "tflite"):
        a = agreement[k]
        rows.append(_row(f"labels equal to Keras ({k})", "", f"{a['same_labels']}/{a['frames']}", "", "all",
                         "yes" if a["same_labels"] == a["frames"] else "no"))
    acc_k, acc_q = quant["keras_accuracy"], quant["tflite_dynamic_range_accuracy"]
    rows.append(_row("quantised (dynamic-range) TFLite test accuracy change, points", f"{acc_k:.3f}", f"{acc_q:.3f}",
                     f"{quant['change_points']:+.2f}", "|change| < 0.5", "yes" if abs(quant["change_points"]) < 0.5 else "no"))
    return rows


def _write(out: Path, result: dict, rows: list[dict]) -> None:
    """Write <out>/bench.json and the table <out>/bench.md / bench.csv, and print the table."""
    import pandas as pd


    info = result["data"]
    report.write_json(out / "bench.json", result)
    note = (f"Run {result['date']} on {result['cpu']}, {'random frames' if info['random_frames'] else info['dataset']}"
            f"{', --quick' if result['quick'] else ''}. Reference: cv2 preprocessing + Keras model.predict + Python "
            f"dictionary loop; ours: greenloop.methods.dictionary.stream.Detector (default backend {result['default_backend']}). "
            f"Reference and ours interleaved in one process; tflite-int8 is the dynamic-range quantised "
            f"export, judged by its test-accuracy change, not by label equality.")
    md = report.write_table(pd.DataFrame(rows), out / "bench", title="Speed: reference vs greenloop.methods.dictionary.stream", note=note)
    print(md.read_text())
