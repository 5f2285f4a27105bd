"""Verification: appearance proposes, geometry confirms. A stage any registered detector can put
after its candidates (the best match of a query, or its top few): :func:`verify_closures` over a
list, a :class:`Verifier` fed query by query in a stream, a :class:`PairCheck` fed candidate by
candidate with their frames (what ``detect`` runs, through ``registry.verifier``).

The pair check (:func:`verify_pair`): ORB features (3000 per frame) on the two frames at their
native resolution, matched by Lowe's ratio test (0.8) and a mutual nearest-neighbour check; then
the geometry by OpenCV's USAC MAGSAC++: the essential matrix with the intrinsics and
``recoverPose`` (its inliers: the points that fit and lie in front of both cameras), and a
homography; the homography is the model when n_H / (n_H + n_E) > 0.45 (ORB-SLAM's initialiser),
a planar scene or a rotation. With depth, the metric pose by RANSAC PnP (3-D points from the match
frame's depth, else the query's) is the model wherever it has at least ``min_inliers`` inliers.

**The rule** (:class:`Rule`, stated once): a candidate is accepted when its model has at least
``min_inliers`` = 50 inliers and ``min_ratio`` = 30 % of the points it was fitted on are inliers
(ORB-SLAM2 closes a loop at 40 matches after its Sim3; the synthetic greenhouse's neighbouring
aisle, a repetitive scene, gives wrong poses with inlier counts just below 50). Frames whose
shorter side is below ``min_side`` = 240 px are 'too-small': not checked, accepted False,
reported unverified (Nordland's 64x32, a 160x120 corridor, 320x180, where the rule keeps few of
the loops it keeps at 640x360). The defaults come from the measurements of
``tools/verification_measure.py`` (results/verification/summary.md): Gardens Point's loop and
other-place pairs at several sizes, the greenhouse's loops, neighbouring aisle and other places.

**Consistency** (:class:`Consistency`): a closure is declared only once k = 3 consecutive verified
candidates agree with the motion (the match advancing with the query, forwards or backwards,
within tol = 5 frames per step), as ORB-SLAM3 and pyslam ask for 3 consistent detections.

**Conventions**: R, t of a :class:`Verification` are the pose T_match_query = T_match^-1 T_query
(camera-to-world poses as CameraTrajectory.txt holds them): X_match = R X_query + t maps a point
of the query camera into the match camera, OpenCV camera axes (x right, y down, z forward); t in
metres where ``metric`` (PnP with depth) else a unit direction (zeros where a homography says the
camera only rotated). Intrinsics are ``datasets.sequence.read_camera``'s record; a folder without
camera.yaml gets :func:`default_camera` (a 60 degree horizontal field of view).
"""
from greenloop.methods.verification.camera import camera_for, default_camera, DEFAULT_HFOV_DEG
from greenloop.methods.verification.closures import Closure, PairCheck, verify_closures, Verifier
from greenloop.methods.verification.consistency import Consistency, DEFAULT_K, DEFAULT_TOL
from greenloop.methods.verification.pair import (DEFAULT_RULE, MODELS, Rule, too_small, Verification,
                                                 verify_pair)

__all__ = ["verify_pair", "verify_closures", "Verifier", "PairCheck", "Verification", "Closure", "Rule", "DEFAULT_RULE", "MODELS",
           "Consistency", "DEFAULT_K", "DEFAULT_TOL", "too_small", "camera_for", "default_camera",
           "DEFAULT_HFOV_DEG"]
