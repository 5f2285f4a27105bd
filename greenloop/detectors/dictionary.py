"""The main paper's detector as a registered one: CNN spots + frequency dictionary at tau = L + Δ.

It declares closures and gives no per-query score (``Entry.score`` is None): :func:`decide`
trains the spot CNN on the original frames before the evaluation part only (every frame without a
split), predicts every frame's spot, and scores the declared pairs on the evaluation queries
(``dictionary.query_closures``, ``evaluate.operating_point``). Its stream is
``speed.stream.Detector`` (the CLI's ``detect --method dictionary``), timed by
``speed.timing.dictionary_method``.

params read: frames_per_spot, seeds, epochs, batch_size, margin, exclude (ORIGINAL frames) and
timing_window ((start, stop) described indices: training stops at the window's first frame).
"""
from __future__ import annotations

import numpy as np

from greenloop import cnn, evaluate, spots
from greenloop import dictionary as counts
from greenloop.datasets import sequence
from greenloop.detectors.interface import Data, Entry, no_descriptors
from greenloop.speed import stream, timing

NAME = "dictionary"


def label(margin: int, tau: int) -> str:
    """The dictionary's leaderboard row name."""
    return f"main paper: CNN + dictionary, tau = L + {margin} = {tau}"


def decide(data: Data) -> dict:
    """Train, predict, declare and score (the chain of notebook 13; module doc).

    Returns dict(name, tau, n_train (original frames trained on), closures (``query_closures`` on
    the evaluation queries), op (``operating_point``), method (``speed.timing.Method``), preload
    (spot labels of the frames before the timed window), text (one line for the notebook))."""
    p, frames = data.params, np.asarray(data.frames)
    start = int(p["timing_window"][0])
    Xg = sequence.load_frames(data.dataset)
    y = spots.group(len(Xg), p["frames_per_spot"])
    n_train = int(frames[start]) if data.tune is not None else len(Xg)
    run = cnn.run_seeds(Xg[:n_train], y[:n_train], list(p["seeds"])[:1], epochs=p["epochs"],
                        batch_size=p["batch_size"], progress=False)[0]
    pred = cnn.predict(run["model"], Xg)
    tau = int(p["frames_per_spot"] + p["margin"])
    declared = counts.declared_pairs(pred, y, tau, p["exclude"])[np.ix_(frames, frames)]
    name = label(p["margin"], tau)
    text = (f"CNN trained on original frames 0..{n_train - 1} "
            f"({'before the evaluation part' if data.tune is not None else 'every frame: no split'}), "
            f"seed {run['seed']}, held-out accuracy {run['test_accuracy']:.3f}; tau = {tau}")
    return {"name": name, "tau": tau, "n_train": n_train,
            "closures": counts.query_closures(declared, data.GT, queries=data.evalq),
            "op": evaluate.operating_point(declared, data.GT, data.exclude, queries=data.evalq),
            "method": timing.dictionary_method(name, stream.Detector(run["model"], tau)),
            "preload": pred[:int(frames[start])], "text": text}


def tune(data: Data) -> tuple[list, dict, dict]:
    """No knob: tau = L + margin is fixed in advance."""
    return [], {}, {}


ENTRY = Entry(NAME, no_descriptors, tune, None, None, None, lambda k: "tau = L + margin", decide=decide)
