"""The main paper's detector as a registered one: CNN spots + frequency dictionary at tau = L + Δ.

It declares closures and gives no per-query score (``Entry.score`` is None): :func:`decide`
runs ``dictionary.operating_points`` (the one chain, notebook 07's too): the spot CNN trained on the
original frames before the evaluation part only (every frame without a split), every frame's spot
predicted, the declared pairs scored on the evaluation queries. Its stream is
``methods.dictionary.stream.Detector`` (the CLI's ``detect --method dictionary``), which the leaderboard
times with ``speed.timing.dictionary_method``.

params read: frames_per_spot, seeds, epochs, batch_size, margin, exclude (ORIGINAL frames) and
timing_window ((start, stop) described indices: training stops at the window's first frame).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from greenloop.datasets import sequence
from greenloop.methods.dictionary import dictionary as counts, stream
from greenloop.methods.greenloop_seq import seqmatch
from greenloop.methods.interface import Data, Entry, no_descriptors

NAME = "dictionary"


def label(margin: int, tau: int) -> str:
    """The dictionary's leaderboard row name."""
    return f"main paper: CNN + dictionary, tau = L + {margin} = {tau}"


def decide(data: Data) -> dict:
    """Train, predict, declare and score (the chain of notebook 13; module doc).

    Returns dict(name, tau, n_train (original frames trained on), closures (``query_closures`` on
    the evaluation queries), op (``operating_point``), detector (its ``stream.Detector``), preload
    (spot labels of the frames before the timed window), text (one line for the notebook))."""
    p, frames = data.params, np.asarray(data.frames)
    start = int(p["timing_window"][0])
    Xg = sequence.load_frames(data.dataset)
    n_train = int(frames[start]) if data.tune is not None else len(Xg)
    tau = int(p["frames_per_spot"] + p["margin"])
    spot, (point,) = counts.operating_points(Xg, p["frames_per_spot"], [tau], frames, data.GT, p["exclude"],
                                             data.exclude, n_train=n_train, queries=data.evalq,
                                             seed=list(p["seeds"])[0], progress=False, epochs=p["epochs"],
                                             batch_size=p["batch_size"])
    run, pred = spot.run, spot.pred
    name = label(p["margin"], tau)
    text = (f"CNN trained on original frames 0..{n_train - 1} "
            f"({'before the evaluation part' if data.tune is not None else 'every frame: no split'}), "
            f"seed {run['seed']}, held-out accuracy {run['test_accuracy']:.3f}; tau = {tau}")
    return {"name": name, "tau": tau, "n_train": n_train,
            "closures": point["closures"], "op": point["op"],
            "detector": stream.Detector(run["model"], tau),
            "preload": pred[:int(frames[start])], "text": text}


def tune(data: Data) -> tuple[list, dict, dict]:
    """No knob: tau = L + margin is fixed in advance."""
    return [], {}, {}


CLI_KNOBS = dict(model=None, frames_per_spot=None, margin=10, backend="auto")   # detect's record: L (unknown), Delta
FRAMES_PER_SPOT = 60   # L where detect is not told the model's: the paper's


def tau(k: dict) -> int:
    """The paper's threshold tau = L + Delta of a knob record (``CLI_KNOBS``' keys; L unknown: FRAMES_PER_SPOT)."""
    return int(k["frames_per_spot"] or FRAMES_PER_SPOT) + int(k["margin"])


def stream_frames(k: dict, threshold, data: Data) -> stream.Detector:
    """``detect --method dictionary``'s streaming detector: the trained CNN ``k["model"]`` (a .keras
    or .tflite file) counting spots to tau = ``threshold`` (an integer >= L; None: :func:`tau`).
    Takes decoded frames (``update_many``); its events are {frame, spot, count}."""
    L = k["frames_per_spot"]
    if L is not None and L < 1:
        raise ValueError(f"--frames-per-spot must be >= 1, got {L}")
    t = tau(k) if threshold is None else threshold
    if int(t) != t:
        raise ValueError(f"--threshold (tau) must be an integer for --method dictionary, got {t:g}")
    if L is not None and t < L:
        raise ValueError(f"--threshold {int(t)} is below --frames-per-spot {k['frames_per_spot']}: the paper's "
                         f"tau = L + margin must be >= L")
    if k["model"] is None:
        raise ValueError(f"--method dictionary needs --model (a trained .keras or .tflite file); without --method, "
                         f"detect runs the named default {seqmatch.DEFAULT_NAME}, which needs no model")
    if not Path(k["model"]).is_file():
        raise FileNotFoundError(f"model file {k['model']} not found: pass a trained .keras model "
                                f"(greenloop.methods.dictionary.cnn.train saves results/models/<key>/model.keras) or "
                                f"a .tflite file (greenloop.methods.dictionary.stream.export_tflite)")
    return stream.Detector(k["model"], int(t), backend=k["backend"])


ENTRY = Entry(NAME, no_descriptors, tune, None, stream_frames, None, lambda k: "tau = L + margin", decide=decide,
              cli_knobs=CLI_KNOBS, cli_threshold=tau)
