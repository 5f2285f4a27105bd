"""The SIFT bag-of-visual-words extractor (the Qi 2024 hand-crafted reference) and its vocabulary.

``extract_sift`` follows the extractor protocol (``registry.Options``); its time covers SIFT plus
quantisation, not the vocabulary fit.
"""
from __future__ import annotations

import time
import warnings

import cv2
import numpy as np

from greenloop.features.frames import gray_frames
from greenloop.features.registry import Backbone, DEFAULT_VOCAB_SIZE, input_size_of, Options
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook


def _sift_descriptors(gray_frames, progress=False):
    sift = cv2.SIFT_create()
    out = []
    for im in _iter_progress(gray_frames, "SIFT", progress):
        _, d = sift.detectAndCompute(im, None)
        out.append(np.zeros((0, 128), np.float32) if d is None else d.astype(np.float32))
    return out


def _iter_progress(items, desc, progress):
    return tqdm(items, desc=desc, unit="img", disable=not progress)


def _fit_vocabulary(descriptors, size, seed, max_descriptors):
    from sklearn.cluster import MiniBatchKMeans
    D = np.concatenate(descriptors) if descriptors else np.zeros((0, 128), np.float32)
    if len(D) == 0:
        raise ValueError("no SIFT keypoints in these frames: cannot fit a visual vocabulary "
                         "(blank or tiny images?)")
    if len(D) > max_descriptors:
        D = D[np.random.default_rng(seed).choice(len(D), max_descriptors, replace=False)]
    k = int(size)
    if k < 1:
        raise ValueError(f"vocabulary size must be >= 1, got {size}")
    if len(D) < k:
        warnings.warn(f"only {len(D)} SIFT descriptors for a {k}-word vocabulary: using {len(D)} "
                      f"words", UserWarning, stacklevel=4)
        k = len(D)
    km = MiniBatchKMeans(n_clusters=k, random_state=seed, n_init=3,
                         batch_size=max(1024, 3 * k), max_iter=100)
    km.fit(D)
    return km.cluster_centers_.astype(np.float32)


def fit_vocabulary(frames_or_folder, size: int = DEFAULT_VOCAB_SIZE, seed: int = 0,
                   input_size=None, max_descriptors: int = 200_000, limit: int | None = None,
                   progress: bool = False) -> np.ndarray:
    """Fit a SIFT visual vocabulary (k-means centres) on a set of frames.

    frames_or_folder: as ``extract``. size: number of visual words k. seed: k-means and descriptor
    subsampling seed (MiniBatchKMeans, n_init=3). max_descriptors: subsample to at most this many.
    Returns (k, 128) float32 centres, to pass as ``extract(..., backbone='sift_bovw', vocabulary=V)``
    (e.g. fitted on one sequence, applied to another). k shrinks, with a warning, when there are
    fewer descriptors than words.
    """
    gray = gray_frames(frames_or_folder, input_size_of(input_size, None), limit, 1, as_float=False)
    return _fit_vocabulary(_sift_descriptors(gray, progress), size, seed, max_descriptors)


def _quantise(desc: np.ndarray, vocab: np.ndarray, c2: np.ndarray) -> np.ndarray:
    if len(desc) == 0:
        return np.zeros(len(vocab), np.float32)
    d2 = (desc * desc).sum(1, keepdims=True) - 2.0 * desc @ vocab.T + c2[None]
    return np.bincount(d2.argmin(1), minlength=len(vocab)).astype(np.float32)


def extract_sift(b: Backbone, frames_or_folder, source, size, opt: Options):
    """The sift_bovw extractor: frames -> (tf-idf (N, k) float32, s/image, {'vocabulary',
    'vocabulary_fitted_on_input'})."""
    progress, vocabulary, vocab_size, seed = opt.progress, opt.vocabulary, opt.vocab_size, opt.seed
    gray = gray_frames(frames_or_folder, size, opt.limit, opt.step, as_float=False, color=opt.color)
    n = len(gray)
    t0 = time.perf_counter()
    descs = _sift_descriptors(gray, progress)
    t_sift = time.perf_counter() - t0
    fitted = vocabulary is None
    if fitted:
        vocab = _fit_vocabulary(descs, vocab_size, seed, 200_000)
    else:
        vocab = np.asarray(vocabulary, dtype=np.float32)
        if vocab.ndim != 2 or vocab.shape[1] != 128 or len(vocab) < 1:
            raise ValueError(f"vocabulary must be (k, 128) SIFT centres (from fit_vocabulary), "
                             f"got shape {vocab.shape}")
    t0 = time.perf_counter()
    c2 = (vocab * vocab).sum(1)
    counts = np.stack([_quantise(d, vocab, c2) for d in descs])
    # tf-idf (Sivic & Zisserman 2003): tf = n_id / n_d, idf = log(N / n_i) over the described frames
    n_words = counts.sum(1, keepdims=True)
    tf = np.divide(counts, n_words, out=np.zeros_like(counts), where=n_words > 0)
    df = (counts > 0).sum(0)
    idf = np.where(df > 0, np.log(n / np.maximum(df, 1)), 0.0).astype(np.float32)
    X = (tf * idf[None]).astype(np.float32)
    dt = t_sift + time.perf_counter() - t0
    empty = int((n_words[:, 0] == 0).sum())
    if empty:
        warnings.warn(f"sift_bovw: {empty} of {n} frames have no SIFT keypoints (all-zero rows)",
                      UserWarning, stacklevel=3)
    return X, dt / n, {"vocabulary": vocab, "vocabulary_fitted_on_input": fitted}

