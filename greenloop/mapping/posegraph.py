"""A pose graph from odometry and loop closures, optimised with GTSAM, plain or robust.

The graph (Pose3, one variable per frame, key k = frame k):

- a prior on pose 0 at the odometry's first pose (sigma ``Noise.prior``: fixes the gauge);
- one between-factor per consecutive odometry pair, measuring ``inv(O_k) @ O_{k+1}`` with a
  diagonal noise model whose variance grows in proportion to the step's length d_k (metres), as a
  wheel odometry's random walk does (the sum over steps then depends on the distance, not on the
  frame rate): sigma_t = max(``odom_trans_min_m``, ``odom_trans_per_sqrt_m`` * sqrt(d_k)) metres and
  sigma_r = max(``odom_rot_min_deg``, ``odom_rot_deg_per_sqrt_m`` * sqrt(d_k)) degrees, per axis;
- one between-factor per loop closure (:class:`Loop`): ``T_ij = inv(T_w_i) @ T_w_j``, the pose of
  match j's camera in query i's camera frame (points in j's frame mapped into i's), sigma
  ``loop_trans_m`` metres, ``loop_rot_deg`` degrees per axis.

A loop whose translation is known in direction only (``metric=False``, an essential matrix without
depth): its translation is taken as the given unit direction times the odometry's distance between
the two poses (the only scale at hand) and its translation sigma widened to
max(``loop_trans_m``, ``direction_trans_per_m`` * that distance): the factor constrains the
rotation as strongly as a metric loop and the translation weakly (tests/test_mapping.py holds this).

Pose2 (``planar=True``, for a ground robot): the odometry is projected on the plane of its two
axes of largest extent (``trajectory.to_planar``: position on those axes, yaw about their normal),
the loops' relative poses likewise; the optimised planar poses are lifted back by moving each
odometry pose by its planar correction, so its height, pitch and roll stay the odometry's.

Back ends (:data:`METHODS`): ``lm`` plain Levenberg-Marquardt (every loop weight 1.0); ``gnc``
graduated non-convexity with the truncated-least-squares loss (Yang, Antonante, Tzoumas, Carlone,
RA-L 2020; ``gtsam.GncLMOptimizer``, the prior and odometry factors set as known inliers, GTSAM's
default inlier threshold: a factor's cost 0.5 r^T Sigma^-1 r below 0.5 chi2_d(0.99), d = 6 for Pose3,
3 for Pose2), its final weights 0..1 per loop; ``huber``, ``cauchy`` a robust kernel on the loop
factors with plain LM, the weight reported being the kernel's weight at the final residual (labelled
as such: a kernel keeps every loop's pull, down-weighted, where GNC's TLS drops a rejected one).

Not built here: Kimera-RPGO's PCM (each loop checked against the odometry between its ends, then
pairs of loops for mutual consistency, the largest consistent set kept by a maximum clique, before
optimisation) and switchable constraints / DCS (GTSAM's ``mEstimator.DCS`` at Phi = 1 rejected the
true loop of the square test: the drifted odometry's start leaves its residual large).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from greenloop.mapping import trajectory as tj

METHODS = ("lm", "gnc", "huber", "cauchy")
# kernel widths in whitened units (Mahalanobis distance): Huber's and Cauchy's 95 %-efficiency constants
KERNEL_WIDTH = {"huber": 1.345, "cauchy": 2.3849}
# GNC re-solves the graph from the odometry at every step of its schedule (GTSAM's mu step 1.4, the
# paper's): each inner Levenberg-Marquardt stops at a relative error decrease of 1e-3, not 1e-5, which
# more than halved the time on a 10,000-pose graph with as many false loops as true ones, with the
# same ATE and the same loops kept (tools/posegraph_measure.py)
GNC_INNER_TOL = 1e-3


class Loop(NamedTuple):
    """One loop closure: query frame i, match frame j, T (4, 4) = ``inv(T_w_i) @ T_w_j`` (match j's
    camera pose in query i's camera frame, metres), metric: False when T's translation is a
    direction only (its length is ignored; module doc)."""
    i: int
    j: int
    T: np.ndarray
    metric: bool = True


class Noise(NamedTuple):
    """The graph's noise model (module doc), standard deviations per axis. Odometry: translation
    ``odom_trans_per_sqrt_m`` metres and rotation ``odom_rot_deg_per_sqrt_m`` degrees times the square
    root of the step's metres, floored at ``odom_trans_min_m`` / ``odom_rot_min_deg``; generous on
    purpose: GNC's inlier test judges a loop by its residual against these, and an odometry sigma
    below its real drift makes true loops look like outliers. Loops: ``loop_trans_m`` metres,
    ``loop_rot_deg`` degrees; a direction-only loop's translation: ``direction_trans_per_m`` times the
    odometry's distance between its poses. ``prior``: pose 0's sigma (radians and metres)."""
    odom_trans_per_sqrt_m: float = 0.1
    odom_rot_deg_per_sqrt_m: float = 3.0
    odom_trans_min_m: float = 0.01
    odom_rot_min_deg: float = 0.1
    loop_trans_m: float = 0.2
    loop_rot_deg: float = 2.0
    direction_trans_per_m: float = 1.0
    prior: float = 1e-6


class Result(NamedTuple):
    """poses (N, 4, 4) optimised; weights (L,) each loop factor's final weight (1.0 for lm);
    method: the back end."""
    poses: np.ndarray
    weights: np.ndarray
    method: str


def _gtsam():
    """The gtsam module, imported on first use (a heavy library: importing greenloop stays cheap)."""
    import gtsam
    return gtsam


class _Space(NamedTuple):
    """Pose3 or Pose2 in GTSAM: axes None (Pose3) or the plane's two axes (Pose2, yaw about their
    normal); the types, and the order of a noise model's sigmas."""
    axes: tuple[int, int] | None

    def pose(self, T):
        """A (4, 4) pose (planar already for Pose2) as a GTSAM Pose3 / Pose2."""
        g = _gtsam()
        return g.Pose3(T) if self.axes is None else g.Pose2(*tj.to_planar(T, self.axes)[0])

    def sigmas(self, rot_rad, trans_m):
        """A diagonal noise model: Pose3 (r, r, r, t, t, t), Pose2 (t, t, r): GTSAM's tangent orders."""
        s = [rot_rad] * 3 + [trans_m] * 3 if self.axes is None else [trans_m, trans_m, rot_rad]
        return _gtsam().noiseModel.Diagonal.Sigmas(np.array(s, dtype=np.float64))

    def prior(self, key, T, model):
        """A prior factor on key at the (4, 4) pose T."""
        g = _gtsam()
        return (g.PriorFactorPose3 if self.axes is None else g.PriorFactorPose2)(key, self.pose(T), model)

    def between(self, i, j, T, model):
        """A between-factor measuring the (4, 4) relative pose T = inv(X_i) X_j."""
        g = _gtsam()
        return (g.BetweenFactorPose3 if self.axes is None else g.BetweenFactorPose2)(i, j, self.pose(T), model)

    def flat(self, poses) -> np.ndarray:
        """(N, 4, 4) poses as the graph sees them: as given (Pose3), projected on the plane (Pose2)."""
        return poses if self.axes is None else tj.from_planar(tj.to_planar(poses, self.axes), self.axes)

    def poses(self, values, odometry) -> np.ndarray:
        """(N, 4, 4) optimised poses: Pose3 as they are; Pose2 lifted, each odometry pose moved by the
        planar correction (its in-plane shift and yaw) that takes its projection to the optimum."""
        g = _gtsam()
        if self.axes is None:
            m = g.utilities.extractPose3(values)
            out = np.tile(np.eye(4), (len(m), 1, 1))
            out[:, :3, :3], out[:, :3, 3] = m[:, :9].reshape(-1, 3, 3), m[:, 9:]
            return out
        opt = tj.from_planar(g.utilities.extractPose2(values), self.axes)
        return opt @ tj.inverse(self.flat(odometry)) @ odometry


def check_loops(loops, n_poses: int) -> list[Loop]:
    """``loops`` as a list of :class:`Loop` (any records with i, j, T[, metric]); ValueError naming a
    loop whose frames lie outside 0..n_poses-1, that joins a frame to itself, or whose T is no pose."""
    out = []
    for k, rec in enumerate(loops):
        loop = Loop(*rec) if not isinstance(rec, Loop) else rec
        i, j = int(loop.i), int(loop.j)
        if not (0 <= i < n_poses and 0 <= j < n_poses) or i == j:
            raise ValueError(f"loop {k} joins frames {i} and {j}: both must lie in 0..{n_poses - 1} and differ")
        T = tj.check_poses(np.asarray(loop.T)[None], f"loop {k}'s T")[0]
        out.append(Loop(i, j, T, bool(loop.metric)))
    return out


def loop_measurement(loop: Loop, odometry: np.ndarray, noise: Noise) -> tuple[np.ndarray, tuple[float, float]]:
    """The (4, 4) measurement and (rotation sigma rad, translation sigma m) of one loop factor: as
    given for a metric loop; for a direction-only loop the unit direction times the odometry's
    distance between the two poses, with the widened translation sigma (module doc)."""
    T = loop.T.copy()
    sigma_t = noise.loop_trans_m
    if not loop.metric:
        d = float(np.linalg.norm(odometry[loop.j, :3, 3] - odometry[loop.i, :3, 3]))
        n = np.linalg.norm(T[:3, 3])
        T[:3, 3] = T[:3, 3] / n * d if n > 0 else 0.0
        sigma_t = max(noise.loop_trans_m, noise.direction_trans_per_m * d)
    return T, (np.radians(noise.loop_rot_deg), sigma_t)


def _space(odometry, planar: bool) -> _Space:
    """Pose3, or Pose2 in the plane of the odometry's two axes of largest extent."""
    return _Space(tj.plane_axes(odometry) if planar else None)


def build_graph(odometry, loops, noise: Noise = Noise(), kernel: str | None = None, planar: bool = False):
    """The pose graph (module doc) of odometry (N, 4, 4) and loops (:class:`Loop` records).

    kernel: None (Gaussian loop factors) or a key of KERNEL_WIDTH (a robust kernel on the loop
    factors). planar: Pose2 in the odometry's plane (module doc) instead of Pose3. Returns (graph,
    initial values (the odometry), loop factor indices (L,) int): factor 0 is the prior, 1..N-1 the
    odometry, N.. the loops in their order.
    """
    gtsam = _gtsam()
    odo = tj.check_poses(odometry, "odometry")
    loops = check_loops(loops, len(odo))
    space = _space(odo, planar)
    flat = space.flat(odo)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for k, T in enumerate(flat):
        values.insert(k, space.pose(T))
    graph.add(space.prior(0, flat[0], space.sigmas(noise.prior, noise.prior)))
    motion = tj.steps(flat) if len(flat) > 1 else np.zeros((0, 4, 4))
    d = np.linalg.norm(tj.steps(odo)[:, :3, 3], axis=1) if len(odo) > 1 else np.zeros(0)
    s_t = np.maximum(noise.odom_trans_min_m, noise.odom_trans_per_sqrt_m * np.sqrt(d))
    s_r = np.radians(np.maximum(noise.odom_rot_min_deg, noise.odom_rot_deg_per_sqrt_m * np.sqrt(d)))
    for k, M in enumerate(motion):
        graph.add(space.between(k, k + 1, M, space.sigmas(s_r[k], s_t[k])))
    first = graph.size()
    for loop in loops:
        T, (sr, st) = loop_measurement(loop, odo, noise)
        model = space.sigmas(sr, st)
        if kernel is not None:
            model = gtsam.noiseModel.Robust.Create(_kernel(kernel), model)
        graph.add(space.between(loop.i, loop.j, space.flat(T[None])[0], model))
    return graph, values, np.arange(first, graph.size())


def _kernel(name: str):
    """The GTSAM m-estimator of a KERNEL_WIDTH name at its width."""
    m = _gtsam().noiseModel.mEstimator
    make = {"huber": m.Huber, "cauchy": m.Cauchy}[name]
    return make.Create(KERNEL_WIDTH[name])


def _lm_params(relative_tol: float = 1e-5):
    """Levenberg-Marquardt at GTSAM's defaults (relative error decrease tolerance 1e-5 unless given),
    silent, at most 100 iterations."""
    p = _gtsam().LevenbergMarquardtParams()
    p.setMaxIterations(100)
    p.setRelativeErrorTol(relative_tol)
    return p


def _kernel_weights(graph, values, index, kernel: str) -> np.ndarray:
    """The robust kernel's weight at each loop factor's final Mahalanobis distance, (L,)."""
    k = _kernel(kernel)
    out = []
    for f in index:
        factor = graph.at(int(f))
        r = factor.unwhitenedError(values)
        gauss = factor.noiseModel().noise()
        out.append(k.weight(float(np.linalg.norm(gauss.whiten(r)))))
    return np.asarray(out, dtype=np.float64)


def optimize(odometry, loops, method: str = "gnc", noise: Noise = Noise(), planar: bool = False) -> Result:
    """Optimise the pose graph of odometry (N, 4, 4) and loops (:class:`Loop` records) with one back
    end of METHODS (module doc), in Pose3 or (``planar``) Pose2. Returns a :class:`Result`: the poses
    (N, 4, 4) and each loop's final weight (L,): GNC's weight (about 0: rejected, 1: kept), the
    kernel's weight, or 1.0 (lm)."""
    gtsam = _gtsam()
    if method not in METHODS:
        raise ValueError(f"unknown back end {method!r}: choose one of {', '.join(METHODS)}")
    kernel = method if method in KERNEL_WIDTH else None
    odo = tj.check_poses(odometry, "odometry")
    graph, values, index = build_graph(odo, loops, noise, kernel, planar)
    if method == "gnc" and len(index):
        params = gtsam.GncLMParams(_lm_params(GNC_INNER_TOL))
        params.setKnownInliers([int(k) for k in range(int(index[0]))])
        opt = gtsam.GncLMOptimizer(graph, values, params)
        result = opt.optimize()
        weights = np.asarray(opt.getWeights(), dtype=np.float64)[index]
    else:
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, _lm_params()).optimize()
        weights = _kernel_weights(graph, result, index, kernel) if kernel else np.ones(len(index))
    return Result(_space(odo, planar).poses(result, odo), weights, method)


def loop_from_closure(query: int, match: int, R, t, metric: bool) -> Loop:
    """The loop factor of a verified closure: R (3, 3), t (3,) its pose T_match_query (X_match = R X_query
    + t, the convention of ``methods.verification`` and of detect's --matches columns), t in metres where
    ``metric`` else a unit direction. The Loop holds the inverse, T_query_match = inv(T_w_query) T_w_match."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = np.asarray(R, dtype=np.float64), np.asarray(t, dtype=np.float64)
    return Loop(int(query), int(match), tj.inverse(T), bool(metric))


def loops_from_poses(poses, pairs, metric: bool = True) -> list[Loop]:
    """True loops from known poses (N, 4, 4) at index pairs (P, 2) (query i, match j): T_ij =
    ``inv(T_i) @ T_j``; with ``metric=False`` its translation is kept as a unit direction."""
    p = tj.check_poses(poses)
    out = []
    for i, j in np.asarray(pairs, dtype=np.int64).reshape(-1, 2):
        T = tj.relative(p[i], p[j])
        if not metric:
            n = np.linalg.norm(T[:3, 3])
            T[:3, 3] = T[:3, 3] / n if n > 0 else 0.0
        out.append(Loop(int(i), int(j), T, metric))
    return out


def inject_false_loops(loops, n_poses: int, fraction: float, seed: int, positions=None,
                       min_gap: int | None = None, min_distance_m: float = 5.0) -> tuple[list[Loop], np.ndarray]:
    """Add wrong loop factors so that they make ``fraction`` (0 <= fraction < 1) of all loop factors.

    loops: the true loops (:class:`Loop` records); n_poses: the graph's poses. Each false loop joins
    a random pair (i, j) at least ``min_gap`` frames apart (default n_poses // 10) and, when
    ``positions`` (N, 3) metres (the ground truth) are given, at least ``min_distance_m`` metres apart,
    with a plausible-looking relative pose: a random true loop's T (else a small random motion, up to
    10 degrees and 0.5 m), metric. Their number is round(fraction * L / (1 - fraction)) for L true
    loops. Returns (the true loops then the false ones, is_false (L + F,) bool). Seeded.
    """
    if not 0 <= fraction < 1:
        raise ValueError(f"fraction must be in [0, 1), got {fraction}")
    true = check_loops(loops, n_poses)
    n_false = int(round(fraction * len(true) / (1 - fraction)))
    gap = max(1, n_poses // 10) if min_gap is None else int(min_gap)
    rng = np.random.default_rng(seed)
    false, tries = [], 0
    while len(false) < n_false:
        tries += 1
        if tries > 1000 * max(n_false, 1):
            raise ValueError(f"found no pair of frames {gap} frames and {min_distance_m} m apart: lower "
                             f"min_gap or min_distance_m")
        i, j = (int(v) for v in rng.integers(0, n_poses, 2))
        if abs(i - j) < gap or (positions is not None and
                                np.linalg.norm(np.asarray(positions)[i] - np.asarray(positions)[j]) < min_distance_m):
            continue
        false.append(Loop(max(i, j), min(i, j), _plausible(true, rng), True))
    return true + false, np.array([False] * len(true) + [True] * len(false))


def _plausible(true: list[Loop], rng) -> np.ndarray:
    """A (4, 4) relative pose that looks like a loop's: a random true loop's (metric ones first), else
    a random motion of up to 10 degrees about a random axis and up to 0.5 m."""
    metric = [lp for lp in true if lp.metric] or true
    if metric:
        return metric[int(rng.integers(len(metric)))].T.copy()
    axis = rng.standard_normal(3)
    direction = rng.standard_normal(3)
    return tj.make_poses(axis / np.linalg.norm(axis) * np.radians(rng.uniform(0, 10)),
                         direction / np.linalg.norm(direction) * rng.uniform(0, 0.5))[0]
