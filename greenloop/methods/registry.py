"""The one registry of detectors: {name: ``interface.Entry``}, in leaderboard order.

Notebook 13's leaderboard (``greenloop.experiments.leaderboard``) describes, tunes, scores, streams
and times every entry in this order; ``python -m greenloop detect --method NAME`` offers every
name; tests/test_detectors.py checks each entry's stream against its score matrix. A new
detector: its module in ``greenloop/methods/`` and one line in ``ENTRIES``.

It is also the only door a user's run (``greenloop.detect``, ``greenloop.cli``) has into
``methods/``: the default's name (:data:`DEFAULT`), the index options (:data:`INDEX`), what a
user's stream is given (:func:`user_params`), a detector built (:func:`stream`) and read
(:func:`best_candidate`), and the geometric verifier (:func:`verifier`).
"""
from __future__ import annotations

from greenloop.methods.dictionary import entry as dictionary
from greenloop.methods.greenloop_seq import entry as greenloop_seq, seqmatch, seqstream
from greenloop.methods.interface import Data, IndexOptions
from greenloop.methods.lsh import retrieval
from greenloop.methods.seqslam import entry as seqslam
from greenloop.methods.siamese import entry as scnn
from greenloop.methods.single_frame import cnn_layers, entry as single_frame
from greenloop.methods import verification

ENTRIES = (
    single_frame.ENTRY,            # "single-frame": CNNs, SIFT-BoVW, pixels
    cnn_layers.ENTRY,              # "cnn-layers": each network's layer and pooling chosen on the tuning part
    scnn.ENTRY,                    # "siamese": Xu 2022's Siamese CNN, trained before the evaluation part
    greenloop_seq.ENTRY,           # "greenloop-seq": greenloop-seq, greenloop-seq-fast
    seqslam.ENTRY,                 # "seqslam": SeqSLAM (tuned), SeqSLAM (published)
    greenloop_seq.DEFAULT_ENTRY,   # "greenloop-seq-grad": the named default, untuned
    greenloop_seq.CNN_ENTRY,       # "greenloop-seq-cnn": the named CNN configuration, untuned
    dictionary.ENTRY,              # "dictionary": the main paper's CNN + dictionary
)
REGISTRY = {e.name: e for e in ENTRIES}


def get(name: str, registry=None):
    """The entry called ``name`` (of ``registry``, default :data:`REGISTRY`); ValueError naming
    the registered ones otherwise."""
    reg = REGISTRY if registry is None else registry
    if name not in reg:
        raise ValueError(f"no detector {name!r}: registered are {list(reg)} (greenloop/methods/registry.py)")
    return reg[name]

DEFAULT = greenloop_seq.DEFAULT_ENTRY.name     # ``detect`` with no --method: the named default
INDEX = IndexOptions(retrieval.KINDS, seqstream.INDEX_DIM, seqstream.INDEX_FIT, seqstream.NULL_SAMPLE)
STORE_DTYPES = seqmatch.STORE_DTYPES      # the sequence matcher's stored-row types (detect --store-dtype)


def named() -> dict:
    """{name: fixed threshold} of the named configurations: the entries whose ``cli_knobs`` carry a
    ``fixed_threshold`` (they stream with no tuning), in registry order."""
    return {e.name: e.cli_knobs["fixed_threshold"] for e in ENTRIES if e.cli_knobs and "fixed_threshold" in e.cli_knobs}


def user_params(index=None, candidates: int = 20) -> dict:
    """``Data.params`` of a user's recording: the default velocities, ImageNet weights, and the
    index options (index: an :data:`INDEX` kind or None; candidates: frames retrieved per query)."""
    return {"velocities": seqmatch.DEFAULT_VELOCITIES, "weights": "auto", "index": index, "candidates": candidates}


def stream(name: str, knobs: dict, threshold, data: Data):
    """Entry ``name``'s streaming detector of ``knobs`` at ``threshold`` on ``data``; with an index
    (``data.params["index"]``) faiss runs on one thread (the per-query latency a robot sees)."""
    if data.params.get("index") is not None:
        retrieval.one_thread()
    return get(name).stream(knobs, threshold, data)


def best_candidate(detector) -> tuple[int, float]:
    """The newest query's best stored candidate of a descriptor-fed streaming detector (after
    ``update_descriptor``): (stored frame number, score), (-1, NaN) without a candidate."""
    return seqstream.best_candidate(detector)


def verifier(camera: dict | None = None):
    """The geometric verifier ``detect`` applies to each closure candidate (``detect.run(verifier=...)``):
    a fresh ``verification.PairCheck`` (it keeps a stream's feature memo and consistency chain), a callable
    (query, match, frame_q, frame_m, depth_q, depth_m) -> ``verification.Verification`` (accepted, inliers,
    model, R, t as T_match_query, metric), frames (H, W, 3) uint8 BGR, depth (H, W) metres or None.
    camera: the recording's intrinsics (``sequence.Sequence.camera()``), None where it has no camera file
    (the verifier then states its default from the image size: ``verification.default_camera``)."""
    return verification.PairCheck(camera)
