"""The extractor of registered frame functions (registry kind "function"): a descriptor that is a
plain function of RGB frames, named in its registry line as ``fn="module:function"``.

The function takes (n, H, W, 3) uint8 RGB frames and returns (n, D) float32 rows; it is called on
batches of ``Options.batch_size`` frames. Frames reach it as a folder's frames decode (RGB, at the
registry line's input size, native when None), whatever the channel order or dtype they came in.
"""
from __future__ import annotations

import functools
import hashlib
import importlib
import marshal
import time
from pathlib import Path

import numpy as np

from greenloop.features.frames import load, rgb_uint8
from greenloop.features.registry import Backbone, Options


@functools.lru_cache(maxsize=None)
def frame_function(spec: str):
    """The function named "module:function" (imported once)."""
    module, _, name = spec.partition(":")
    if not module or not name:
        raise ValueError(f"a 'function' descriptor names its function as 'module:function', got {spec!r}")
    return getattr(importlib.import_module(module), name)


def code_digest(spec: str) -> str:
    """sha1 hex of the code of the function "module:function": its module file's bytes, or where the
    module has no file, the function's marshalled code (the cache keys of its descriptors hash it)."""
    module = importlib.import_module(spec.partition(":")[0])
    path = getattr(module, "__file__", None)
    data = Path(path).read_bytes() if path else marshal.dumps(frame_function(spec).__code__)
    return hashlib.sha1(data).hexdigest()


def extract_function(b: Backbone, frames_or_folder, source, size, opt: Options):
    """The 'function' extractor: frames -> (features (N, D) float32, s/image, {}). Raises ValueError
    when the function does not return one row of b.dim values per frame."""
    fn = frame_function(b.fn)
    a = load(frames_or_folder, size, gray=False, limit=opt.limit, step=opt.step)
    t0 = time.perf_counter()
    rows = [np.asarray(fn(rgb_uint8(a[i:i + opt.batch_size], size, opt.color)), dtype=np.float32)
            for i in range(0, len(a), opt.batch_size)]
    X = np.concatenate(rows)
    if X.shape != (len(a), b.dim):
        raise ValueError(f"{b.fn} returned shape {X.shape} for {len(a)} frames; the registry says {b.name} "
                         f"is {b.dim}-dimensional: (n, {b.dim}) rows, one per frame")
    return X, (time.perf_counter() - t0) / len(a), {}
