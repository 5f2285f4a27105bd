"""Xu 2022's Siamese CNN as a single-frame matcher: trained on the frames before the evaluation part.

One row per supervision of ``params["siamese_rows"]`` (e.g. ["multitask"]), "siamese-<supervision>
(single frame)". Its network (``greenloop.methods.siamese.siamese``, notebook 10's model and training with its
budget: ``siamese_epochs`` x ``siamese_pairs`` pairs, hard negatives, augmentation, seed
``siamese_seeds[0]``) is trained on every described frame that is not an evaluation query nor
within the split's gap (the longest of ``seq_lens``) of one; places are spots of
``frames_per_spot`` original frames, a revisit taking its ground-truth partner's place
(``siamese.place_labels``). Every frame is then described by its fc7 descriptor and matched as
every single-frame row: the cosine of L2-normalised descriptors, whitening and contrast window
picked on the tuning queries by the one budget (``single_frame.tune_names``). Without an honest
split there is no frame to train on that is not also scored, so the family gives no row.
The CLI has no untuned form of it (a network needs a labelled sequence to train on).
"""
from __future__ import annotations

import numpy as np

from greenloop.datasets import sequence
from greenloop.methods.greenloop_seq import entry as greenloop_seq
from greenloop.methods.interface import Data, Entry
from greenloop.methods.siamese import siamese
from greenloop.methods.single_frame import entry as single_frame

NAME = "siamese"


def descriptor_name(supervision: str) -> str:
    """The descriptor (and, with " (single frame)", the row) of a supervision's network."""
    return f"siamese-{supervision}"


def train_kw(params: dict) -> dict:
    """``siamese.train``'s arguments from the leaderboard's params (notebook 10's names)."""
    p = params
    return dict(seed=int(list(p["siamese_seeds"])[0]), epochs=p["siamese_epochs"], n_pairs=p["siamese_pairs"],
                batch_size=p["siamese_batch"], width=p["siamese_width"], hard_fraction=p["hard_fraction"],
                augment_shift=p["augment_shift"], augment_light=p["augment_light"], progress=True)


def training_frames(data: Data) -> np.ndarray:
    """(M,) bool: the described frames a network may train on (neither an evaluation query nor
    within the split's gap, ``max(params["seq_lens"])`` described frames, of one)."""
    return ~siamese.near_heldout(data.evalq, max(data.params["seq_lens"]))


def describe(data: Data) -> tuple[dict, dict]:
    """Each supervision's network, trained (or read from the model cache), and its fc7 descriptors
    of every described frame; the models are kept in ``data.cache["siamese"]`` for the stream."""
    p = data.params
    sups = list(p.get("siamese_rows", ()))
    if not sups or data.tune is None:
        return {}, {}
    size = int(p["siamese_input_size"])
    X = siamese.load_inputs(data.dataset, (size, size), step=data.frame_step, depth=False)
    if len(X) != len(data.frames):
        raise ValueError(f"{data.dataset}: {len(X)} frames at step {data.frame_step}, the ground truth has {len(data.frames)}")
    L = max(1, int(p["frames_per_spot"]) // data.frame_step)
    labels = siamese.place_labels(training_frames(data), data.GT, L)
    out, infos = {}, {}
    for sup in sups:
        name = descriptor_name(sup)
        model, _, _ = siamese.train(X, labels, supervision=sup, gt=data.GT, **train_kw(p))
        out[name], infos[name] = siamese.describe(model, X, return_info=True)
        data.cache.setdefault("siamese", {})[name] = model
    return out, infos


def tune(data: Data) -> tuple[list, dict, dict]:
    """Whitening and contrast window of each network's matcher on the tuning queries."""
    names = [descriptor_name(s) for s in data.params.get("siamese_rows", ()) if descriptor_name(s) in data.descriptors]
    if not names:
        return [], {}, {}
    return single_frame.tune_names(data, names, names)


def describer(k: dict, data: Data):
    """One decoded BGR frame -> its fc7 descriptor (D,): the frame as ``siamese.load_inputs`` reads it."""
    model = data.cache["siamese"][k["descriptor"]]
    size = int(data.params["siamese_input_size"])

    def one(frame):
        x = sequence.preprocess_image(frame, (size, size), gray=False).astype(np.float32) / np.float32(255.0)
        return siamese.describe(model, x[None])[0]
    return one


ENTRY = Entry(NAME, describe, tune, greenloop_seq.score, greenloop_seq.stream, describer, greenloop_seq.knob_text)
