"""One candidate pair checked by its geometry: :func:`verify_pair`, the :class:`Rule` it applies
and the :class:`Verification` it returns (the package docstring states the rule)."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from greenloop.methods.verification import camera as _camera, features, geometry


class Rule(NamedTuple):
    """The one acceptance rule (the package docstring says why these defaults; the measurements:
    tools/verification_measure.py -> results/verification/summary.md).

    min_inliers: a pair is accepted with at least this many inliers of its model ...
    min_ratio: ... and at least this share of the points the model was fitted on inliers.
    min_side: pixels; frames whose shorter side is below it are 'too-small' (unverified).
    features: 'orb' or 'sift'; n_features: keypoints per frame at most; ratio: Lowe's ratio.
    px: inlier threshold of the essential matrix and the homography (pixels); pnp_px: PnP's
    reprojection threshold (pixels).
    h_share: the homography is the model when n_H / (n_H + n_E) > h_share (ORB-SLAM's
    initialiser: 0.45), n_H, n_E the inliers of each fit.
    """
    min_inliers: int = 50
    min_ratio: float = 0.3
    min_side: int = 240
    features: str = "orb"
    n_features: int = 3000
    ratio: float = 0.8
    px: float = 2.0
    pnp_px: float = 3.0
    h_share: float = 0.45


DEFAULT_RULE = Rule()
MODELS = ("essential", "homography", "pnp", "too-small", "none")


class Verification(NamedTuple):
    """What the geometry says about one candidate (query, match).

    accepted: the rule holds (False for 'too-small': unverified, not refuted). inliers: of the
    model; inlier_ratio: inliers / the points the model was fitted on (the matches; for 'pnp' the
    matches with valid depth); matches: ratio-tested, cross-checked matches. model: one of MODELS.
    R: (3, 3) float64, t: (3,) float64, or None: the pose T_match_query (X_match = R X_query + t,
    OpenCV camera axes), t in metres where metric else a unit direction (zeros: rotation only).
    reason: one line saying why it was accepted or not.
    """
    accepted: bool
    inliers: int
    inlier_ratio: float
    matches: int
    model: str
    R: np.ndarray | None
    t: np.ndarray | None
    metric: bool
    reason: str

    @property
    def verified(self) -> bool:
        """True where the geometry could decide (the frames were not too small)."""
        return self.model != "too-small"


def too_small(shape, rule: Rule = DEFAULT_RULE) -> bool:
    """True when an image of ``shape`` (H, W[, C]) is below ``rule.min_side`` on its shorter side."""
    return min(int(shape[0]), int(shape[1])) < rule.min_side


def _none(matches: int, why: str) -> Verification:
    return Verification(False, 0, 0.0, matches, "none", None, None, False, why)


def unverified(shape, rule: Rule = DEFAULT_RULE) -> Verification:
    """The 'too-small' Verification of frames of ``shape`` (H, W[, C]): not accepted, not refuted."""
    return Verification(False, 0, 0.0, 0, "too-small", None, None, False,
                        f"unverified: {shape[1]}x{shape[0]} frames, shorter side < {rule.min_side} px "
                        f"is too small for local features")


def check_sizes(shape_q, shape_m, depth_q=None, depth_m=None) -> None:
    """ValueError unless both frames (shapes (H, W[, C])) have one size and each depth map
    ((H, W) or None) that frame's size."""
    sq, sm = tuple(shape_q[:2]), tuple(shape_m[:2])
    if sq != sm:
        raise ValueError(f"query frame is {sq} but match frame is {sm}: verify frames of one camera "
                         f"at one size")
    for name, d in (("depth_q", depth_q), ("depth_m", depth_m)):
        if d is not None and np.shape(d) != sq:
            raise ValueError(f"{name} is {np.shape(d)} but the frames are {sq}: give depth (H, W) metres "
                             f"registered to the colour frame")


def verify_pair(frame_q, frame_m, camera, depth_q=None, depth_m=None, rule: Rule = DEFAULT_RULE) -> Verification:
    """Check a loop candidate by local features and robust geometry.

    frame_q, frame_m: (H, W, 3) uint8 BGR frames of the query and the matched (earlier) place, at
    native resolution; camera: intrinsics (datasets.sequence.read_camera record, or
    verification.camera_for / default_camera); depth_q, depth_m: (H, W) float metres or None
    (0 / nan: no depth). Returns a :class:`Verification`.
    """
    shape = np.shape(frame_q)
    check_sizes(shape, np.shape(frame_m), depth_q, depth_m)
    if too_small(shape, rule):
        return unverified(shape, rule)
    fq = features.detect(frame_q, rule.features, rule.n_features)
    fm = features.detect(frame_m, rule.features, rule.n_features)
    return verify_features(fq, fm, _camera.matrix(camera, shape), depth_q, depth_m, rule)


def verify_features(fq, fm, K, depth_q=None, depth_m=None, rule: Rule = DEFAULT_RULE) -> Verification:
    """:func:`verify_pair` on features already detected: fq, fm: (points (K, 2), descriptors) of
    ``features.detect``; K: (3, 3) intrinsics of the frames; depth_q, depth_m as verify_pair."""
    pairs = features.match(fq[1], fm[1], rule.features, rule.ratio)
    n = len(pairs)
    if n < 8:
        return _none(n, f"rejected: {n} matches, fewer than 8 to fit a model")
    pq, pm = fq[0][pairs[:, 0]], fm[0][pairs[:, 1]]
    fit, fitted_on = _metric(pq, pm, K, depth_q, depth_m, rule)
    if fit is None:
        fit, fitted_on = _planar_or_general(pq, pm, K, rule.px, rule.h_share), n
    if fit is None:
        return _none(n, f"rejected: no model fits the {n} matches")
    inl = int(fit.inliers.sum())
    share = inl / max(fitted_on, 1)
    ok = inl >= rule.min_inliers and share >= rule.min_ratio
    why = (f"{'accepted' if ok else 'rejected'}: {fit.model} {inl} inliers of {fitted_on} "
           f"({share:.0%}); the rule is >= {rule.min_inliers} and >= {rule.min_ratio:.0%}")
    return Verification(bool(ok), inl, float(share), n, fit.model, fit.R, fit.t, fit.metric, why)


def _metric(pq, pm, K, depth_q, depth_m, rule: Rule):
    """(the PnP Fit, the points it was fitted on) from the match frame's depth (else the query's)
    where it has at least rule.min_inliers inliers; (None, 0) otherwise or without depth."""
    if depth_m is None and depth_q is None:
        return None, 0
    if depth_m is not None:
        X, valid = geometry.back_project(pm, depth_m, K)
        fit = geometry.pnp(pq[valid], X[valid], K, rule.pnp_px, image_is_query=True)
    else:
        X, valid = geometry.back_project(pq, depth_q, K)
        fit = geometry.pnp(pm[valid], X[valid], K, rule.pnp_px, image_is_query=False)
    if fit is None or fit.inliers.sum() < rule.min_inliers:
        return None, 0
    return fit, int(valid.sum())


def _planar_or_general(pq, pm, K, px: float, h_share: float):
    """The homography where n_H / (n_H + n_E) > h_share, else the essential matrix (a Fit or None)."""
    e = geometry.essential(pq, pm, K, px)
    h = geometry.homography(pq, pm, K, px)
    ne = 0 if e is None else int(e.inliers.sum())
    nh = 0 if h is None else int(h.inliers.sum())
    if ne + nh == 0:
        return None
    return h if nh / (ne + nh) > h_share else e
