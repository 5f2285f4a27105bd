"""The one registry of detectors: {name: ``interface.Entry``}, in leaderboard order.

Notebook 13's leaderboard (``greenloop.experiments.leaderboard``) describes, tunes, scores, streams
and times every entry in this order; ``python -m greenloop detect --method NAME`` offers every
name; tests/test_detectors.py checks each entry's stream against its score matrix. A new
detector: its module in ``greenloop/methods/`` and one line in ``ENTRIES``.
"""
from __future__ import annotations

from greenloop.methods.dictionary import entry as dictionary
from greenloop.methods.greenloop_seq import entry as greenloop_seq
from greenloop.methods.seqslam import entry as seqslam
from greenloop.methods.siamese import entry as scnn
from greenloop.methods.single_frame import cnn_layers, entry as single_frame

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
