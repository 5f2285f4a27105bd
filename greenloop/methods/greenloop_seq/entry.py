"""greenloop-seq as a registered detector: the tuned greenloop-seq and greenloop-seq-fast rows and
the two named configurations, never tuned: the named default (``seqmatch.DEFAULT_NAME``, the CLI's
configuration) and the CNN one (``seqmatch.CNN_NAME``).

Also the seqmatch-based pieces the single-frame matchers share (a single-frame matcher is
greenloop-seq's search at seq_len 1): :func:`score`, :func:`stream`, :func:`frame_describer`,
:func:`knob_text`. Knob records: descriptor, whitening (label, "none"), seq_len, contrast_window
and optionally velocities, center_window, calibrate, repeat_cos, cell_shift, store_dtype (the
stream's stored rows, ``seqmatch.STORE_DTYPES``; float32 without it), fixed_threshold.

params read (``Data.params``): seq_descriptors, fast_descriptors, seq_lens, contrast_windows,
velocities, weights, input_size.
"""
from __future__ import annotations

import numpy as np

from greenloop import features
from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.methods.interface import Data, Entry

NAME, FAST = "greenloop-seq", "greenloop-seq-fast"
NAMED = seqmatch.NAMED   # the named configurations: {name: (knobs, fixed threshold)}


def named_default(name: str = seqmatch.DEFAULT_NAME) -> dict:
    """A named configuration of greenloop-seq as a knob record, never tuned here, scored at its
    fixed threshold: the named default (``seqmatch.DEFAULT_NAME``, the CLI's configuration) or the
    CNN one (``seqmatch.CNN_NAME``)."""
    k, t = NAMED[name]
    cw = k["center_window"]
    return dict(k, whitening="none", velocities=list(k["velocities"]), center_window=list(cw) if isinstance(cw, tuple) else cw,
                fixed_threshold=t)


def _extra(k: dict, velocities) -> dict:
    """The seqmatch keyword arguments of a knob record beyond descriptor/seq_len/contrast window."""
    return dict(velocities=tuple(k.get("velocities", velocities)), center_window=k.get("center_window", 0),
                calibrate=k.get("calibrate", False), repeat_cos=k.get("repeat_cos"), cell_shift=k.get("cell_shift", 0),
                store_dtype=k.get("store_dtype", "float32"))


def projection(k: dict, data: Data):
    """The ``similarity.Projection`` of a knob record's whitening label (``data.cache["projections"]``:
    {descriptor: {label: Projection | None}}), None for "none"."""
    if k.get("whitening", "none") == "none":
        return None
    proj = data.cache.get("projections", {}).get(k["descriptor"], {})
    if k["whitening"] not in proj:
        raise ValueError(f"no whitening {k['whitening']!r} fitted for descriptor {k['descriptor']!r} in this run: a "
                         f"projection is fitted on the tuning frames of a leaderboard run (methods.single_frame."
                         f"entry.projections) and is not saved in summary.json; stream a row whose whitening is 'none'")
    return proj[k["whitening"]]


def score(k: dict, data: Data) -> np.ndarray:
    """(M, M) float32 ``seqstream.score_matrix`` of a knob record on ``data.descriptors``."""
    e = _extra(k, data.params["velocities"])
    return seqstream.score_matrix(data.descriptors[k["descriptor"]], data.exclude, k["seq_len"], e.pop("velocities"),
                                 k["contrast_window"], projection(k, data), **e)


def _weights(k: dict, data: Data):
    """The CNN weights of a knob record's descriptor: the run's ``weights`` parameter, except for
    "gradients+efficientnetlite0" and its int8 form (``features.FUSED_INT8``), whose ImageNet weights are
    part of the named CNN configuration (they refuse a random-init network, ``features.resolve``)."""
    fused = (seqmatch.CNN_KNOBS["descriptor"], features.FUSED_INT8)
    return "auto" if k["descriptor"] in fused else data.params.get("weights", "auto")


def stream(k: dict, threshold, data: Data) -> seqstream.Detector:
    """The streaming ``seqstream.Detector`` of a knob record (threshold None or NaN: scores only).
    ``data.params`` "index" (a ``retrieval.KINDS`` name, or None) and "candidates" (k) put it in
    candidate mode, whose index holds the stored rows reduced to ``seqstream.INDEX_DIM`` dims."""
    t = None if threshold is None or not np.isfinite(threshold) else float(threshold)
    desc = k["descriptor"] if k["descriptor"] in seqmatch.DESCRIPTORS else "pixels"
    index = data.params.get("index")
    mode = {} if index is None else dict(index=index, k=data.params.get("candidates", 20), index_dim=seqstream.INDEX_DIM)
    return seqstream.Detector(t, descriptor=desc, seq_len=k["seq_len"], exclude=data.exclude,
                             contrast_window=k["contrast_window"], projection=projection(k, data),
                             weights=_weights(k, data), **_extra(k, data.params["velocities"]), **mode)


def frame_describer(descriptor: str, weights="auto", input_size=None, vocabulary=None):
    """One decoded BGR frame (H, W, 3) uint8 -> the raw descriptor (D,) a method stores: the timed
    describe step. descriptor: a features registry name (``features.get``, made once here, so the
    weights are looked up once); input_size: the study's CNN input. SIFT-BoVW quantises against
    ``vocabulary`` (one frame's tf-idf)."""
    d = features.get(descriptor, weights, cnn_input_size=input_size, vocabulary=vocabulary)
    return lambda f: d(f[None], color="bgr")[0]


def describer(k: dict, data: Data):
    """:func:`frame_describer` of a knob record's descriptor (SIFT-BoVW: the run's vocabulary)."""
    info = data.infos.get("sift_bovw")
    vocab = info.extra.get("vocabulary") if k["descriptor"] == "sift_bovw" and info is not None else None
    return frame_describer(k["descriptor"], _weights(k, data), data.params.get("input_size"), vocab)


def knob_text(k: dict) -> str:
    """One line of a seqmatch knob record for the table."""
    seq = "" if k["seq_len"] == 1 else f", seq_len {k['seq_len']}"
    text = f"{k['descriptor']}, whitening {k['whitening']}, contrast window {k['contrast_window']}{seq}"
    if "fixed_threshold" in k:
        text += (f", centring {k['center_window']}, cell shift {k.get('cell_shift', 0)}, velocities {k['velocities']}, "
                 f"repeat gate {k['repeat_cos']}, store {k.get('store_dtype', 'float32')}, "
                 f"calibrated ({seqmatch.check_calibration(k.get('calibrate', False))}), fixed threshold {k['fixed_threshold']} "
                 f"(the CLI default, untuned)")
    return text


def describe(data: Data) -> tuple[dict, dict]:
    """The sequence descriptors ``data.descriptors`` lacks (``seqmatch.describe``); those already
    there are reused (the same frames, the same values)."""
    X, info = {}, {}
    for d in data.params["seq_descriptors"]:
        if d not in data.descriptors:
            X[d], info[d] = seqmatch.describe(data.dataset, d, step=data.frame_step,
                                              weights=data.params.get("weights", "auto"), return_info=True)
    return X, info


def tune(data: Data) -> tuple[list, dict, dict]:
    """greenloop-seq (every sequence descriptor) and greenloop-seq-fast (the CNN-free ones) on the
    grid seq_lens x contrast_windows, picked by per-query AUC-PR on the tuning queries; nothing
    without a tuning part."""
    p = data.params
    if data.tune is None:
        return [], {}, {}
    X = {d: data.descriptors[d] for d in p["seq_descriptors"]}
    rows = seqstream.tune_knobs(X, data.GT, data.exclude, data.tune, p["seq_lens"], p["contrast_windows"], p["velocities"])
    fast = [d for d in p["fast_descriptors"] if d in p["seq_descriptors"]]
    knobs, best = seqmatch.pick_knobs(rows, {NAME: (list(p["seq_descriptors"]), list(p["seq_lens"])),
                                             FAST: (fast, list(p["seq_lens"]))})
    return rows, knobs, best


def _describe_named(name: str):
    """(Data) -> the named configuration's descriptor where ``data`` lacks it (``Entry.describe``)."""
    def describe_named(data: Data) -> tuple[dict, dict]:
        d = NAMED[name][0]["descriptor"]
        if d in data.descriptors:
            return {}, {}
        X, info = seqmatch.describe(data.dataset, d, step=data.frame_step, return_info=True)
        return {d: X}, {d: info}
    return describe_named


def _tune_named(name: str):
    """(Data) -> a named configuration's record and no tuning rows: it is never tuned (``Entry.tune``)."""
    return lambda data: ([], {name: named_default(name)}, {})


ENTRY = Entry(NAME, describe, tune, score, stream, describer, knob_text, checked=True,
              cli_knobs=dict(descriptor="pixels-patchnorm", whitening="none", seq_len=10, contrast_window=10),
              cli_variant=FAST)   # --tuned streams the CNN-free row unless told otherwise
DEFAULT_ENTRY, CNN_ENTRY = (Entry(n, _describe_named(n), _tune_named(n), score, stream, describer, knob_text,
                                    checked=True, cli_knobs=named_default(n)) for n in NAMED)
