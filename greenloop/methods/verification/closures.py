"""The verification stage over a detector's candidates: :func:`verify_closures` over a list, a
:class:`Verifier` query by query, a :class:`PairCheck` candidate by candidate (detect's), each
declaring ``interface.Closure`` records (query, match, score, verified, inliers, model, R, t, metric)."""
from __future__ import annotations

from collections import OrderedDict
from itertools import groupby
from typing import Callable, NamedTuple

import numpy as np

from greenloop.methods.interface import Closure
from greenloop.methods.verification import camera as _camera, features
from greenloop.methods.verification.consistency import Consistency, DEFAULT_K, DEFAULT_TOL
from greenloop.methods.verification.pair import (check_sizes, DEFAULT_RULE, Rule, too_small, unverified,
                                                 Verification, verify_features)

FEATURE_MEMO = 64    # frames whose features verify_closures keeps (the most recently used)


def closure(query: int, match: int, score: float, v: Verification) -> Closure:
    """The ``interface.Closure`` record of a declared candidate and its :class:`Verification`:
    verified True where the geometry confirmed it, None where the frames were too small to check."""
    return Closure(int(query), int(match), float(score), None if v.model == "too-small" else True,
                   int(v.inliers), v.model, v.R, v.t, bool(v.metric))


class _Features:
    """Features of frames by number, detected once and kept for the FEATURE_MEMO most recent."""

    def __init__(self, frames_of: Callable, rule: Rule):
        self.frames_of, self.rule, self.memo = frames_of, rule, OrderedDict()

    def __call__(self, i: int):
        """(frame shape, (points (K, 2), descriptors) or None where the frame is too small) of frame i."""
        if i in self.memo:
            self.memo.move_to_end(i)
        else:
            frame = self.frames_of(i)
            shape = np.shape(frame)
            found = None if too_small(shape, self.rule) else features.detect(frame, self.rule.features,
                                                                                 self.rule.n_features)
            self.memo[i] = (shape, found)
            if len(self.memo) > FEATURE_MEMO:
                self.memo.popitem(last=False)
        return self.memo[i]


def _check_candidates(candidates) -> list[tuple[int, int, float]]:
    """candidates as [(query int, match int, score float)] in non-decreasing query order."""
    out = [(int(q), int(m), float(s)) for q, m, s in candidates]
    if any(b[0] < a[0] for a, b in zip(out, out[1:])):
        raise ValueError("candidates must come in query order (causal, as a stream gives them): "
                         "sort them by query frame")
    return out


class Verifier:
    """The verification stage of one stream, fed query by query (what :func:`verify_closures`
    runs over a list): the feature memo (at most FEATURE_MEMO frames) and the :class:`Consistency`.

    frames_of, camera, depth_of, rule, k, tol: as :func:`verify_closures`.
    """

    def __init__(self, frames_of: Callable, camera, depth_of: Callable | None = None,
                 rule: Rule = DEFAULT_RULE, k: int = DEFAULT_K, tol: int = DEFAULT_TOL):
        self.camera, self.depth_of, self.rule = camera, depth_of, rule
        self.features, self.consistency = _Features(frames_of, rule), Consistency(k, tol)

    def update(self, query: int, candidates) -> Closure | None:
        """One query's candidates [(match, score), ...] (best score tried first until one is
        accepted) -> the Closure declared for it (verified, or unverified for too-small frames),
        or None."""
        ranked = sorted(((int(m), float(s)) for m, s in candidates), key=lambda c: -c[1])
        if not ranked:
            return None
        for m, score in ranked:
            v = _verify(self.features, int(query), m, self.camera, self.depth_of, self.rule)
            if v.model == "too-small":
                return closure(query, m, score, v)
            if v.accepted:
                return closure(query, m, score, v) if self.consistency.update(query, m, True) else None
        self.consistency.update(query, ranked[0][0], False)
        return None


def verify_closures(frames_of, candidates, camera, depth_of=None, rule: Rule = DEFAULT_RULE,
                    k: int = DEFAULT_K, tol: int = DEFAULT_TOL) -> list[Closure]:
    """Verify a detector's loop candidates by geometry and temporal consistency.

    frames_of: frame number -> (H, W, 3) uint8 BGR frame at native resolution (a callable).
    candidates: (query, match, score) triples in query order, one or several per query (its top
    few; tried best score first until one is accepted). camera: intrinsics (read_camera record,
    verification.camera_for / default_camera). depth_of: frame number -> (H, W) metres or None.
    rule: the acceptance rule; k, tol: the consistency (:class:`Consistency`).
    Returns the declared closures in query order: each query's accepted candidate once its chain
    holds k agreeing candidates (verified=True), and, for frames too small for local features,
    each query's best candidate unverified (verified=False). A stream feeds a :class:`Verifier`.
    """
    verifier = Verifier(frames_of, camera, depth_of, rule, k, tol)
    out = []
    for q, group in groupby(_check_candidates(candidates), key=lambda c: c[0]):
        closure = verifier.update(q, [(m, s) for _, m, s in group])
        if closure is not None:
            out.append(closure)
    return out


def _verify(feats: _Features, q: int, m: int, camera, depth_of, rule: Rule) -> Verification:
    """:func:`verify_pair` of frames q and m through the feature memo."""
    (shape, fq), (shape_m, fm) = feats(q), feats(m)
    depth = (None, None) if depth_of is None else (depth_of(q), depth_of(m))
    check_sizes(shape, shape_m, *depth)
    if fq is None:
        return unverified(shape, rule)
    return verify_features(fq, fm, _camera.matrix(camera, shape), *depth, rule=rule)


class PairCheck:
    """The verification stage of one ``detect`` run, called once per closure candidate with its
    decoded frames: the pair check through a feature memo (FEATURE_MEMO frames), then the
    :class:`Consistency`. camera: the recording's intrinsics (read_camera record), or None for
    :func:`camera.default_camera` of the first frame's size; rule, k, tol: as :func:`verify_closures`.
    State: the feature memo and the consistency chain (one object per stream)."""

    def __init__(self, camera=None, rule: Rule = DEFAULT_RULE, k: int = DEFAULT_K, tol: int = DEFAULT_TOL):
        self.camera, self.rule, self._frames = camera, rule, {}
        self.features, self.consistency = _Features(self._frames.__getitem__, rule), Consistency(k, tol)

    def __call__(self, query: int, match: int, frame_q, frame_m, depth_q=None, depth_m=None) -> Verification:
        """The Verification of candidate (query, match): frames (H, W, 3) uint8 BGR, depth (H, W)
        metres or None. ``accepted`` holds only where the geometry holds and the candidate completes
        k consistent ones (its reason says so otherwise); 'too-small' frames pass unverified."""
        q, m = int(query), int(match)
        if self.camera is None:
            self.camera = _camera.default_camera(np.shape(frame_q)[1], np.shape(frame_q)[0])
        self._frames.update({q: frame_q, m: frame_m})
        depths = {q: depth_q, m: depth_m}
        try:
            v = _verify(self.features, q, m, self.camera, depths.__getitem__, self.rule)
        finally:
            self._frames.clear()
        if v.model == "too-small" or self.consistency.update(q, m, v.accepted) or not v.accepted:
            return v
        return v._replace(accepted=False, reason=f"{v.reason}; geometry holds, {self.consistency.length} of "
                                                 f"{self.consistency.k} consistent candidates so far")
