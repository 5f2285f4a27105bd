"""Wheel odometry simulated from true planar poses: ``simulate_odometry`` (a pure function).

The drift model, per step i from pose i-1 to pose i (true planar poses (x, z, yaw)):

* the true motion in the robot's frame at i-1 (forward, sideways, turn dθ) and its length d;
* the wheels read the translation scaled by ``1 + scale_error + slip * sqrt(d) * e_i / d`` (a
  constant wheel-radius error, a fraction, plus a random slip of std ``slip`` metres per
  sqrt(metre) driven);
* the turn reads ``dθ + heading_bias * d + heading_noise * sqrt(d) * h_i`` (a constant heading
  bias in radians per metre driven, from unequal wheels, plus random noise of std
  ``heading_noise`` radians per sqrt(metre));
* e_i, h_i ~ N(0, 1) from ``numpy.random.default_rng(seed)``; the read motions are composed
  from the first true pose on, so the error grows with the distance driven: the heading error
  by ``heading_bias`` per metre, the position error about quadratically in the distance through it.

The same (poses, seed, parameters) give the same odometry. All zero gives back the true poses.
"""
from __future__ import annotations

import numpy as np

SCALE_ERROR = 0.01        # fraction: wheels read 1 % long
SLIP = 0.01               # metres of random slip per sqrt(metre) driven (std)
HEADING_BIAS = 0.005      # radians per metre driven (0.29 degrees per metre)
HEADING_NOISE = 0.002     # radians per sqrt(metre) driven (std)


def simulate_odometry(planar, seed: int = 0, scale_error: float = SCALE_ERROR, slip: float = SLIP,
                      heading_bias: float = HEADING_BIAS, heading_noise: float = HEADING_NOISE) -> np.ndarray:
    """Wheel odometry of a robot that drove the true ``planar`` poses (module doc: drift model).

    planar: (N, 3) true poses (x, z, yaw) in metres and radians, yaw = atan2(dz, dx) of the
    heading in the floor plane; seed: an integer >= 0; the drift parameters as the module doc
    (units: fraction, m / sqrt(m), rad / m, rad / sqrt(m)). Returns (N, 3) odometry poses in the
    same units and frame, equal to the true one at index 0.
    """
    p = np.asarray(planar, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 1 or not np.all(np.isfinite(p)):
        raise ValueError(f"planar must be a finite (N, 3) array of (x, z, yaw) metres and radians, got shape {p.shape}")
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if slip < 0 or heading_noise < 0:
        raise ValueError(f"slip and heading_noise are standard deviations and must be >= 0, got {slip}, {heading_noise}")
    rng = np.random.default_rng(int(seed))
    e, h = rng.standard_normal(len(p) - 1), rng.standard_normal(len(p) - 1)
    c, s = np.cos(p[:-1, 2]), np.sin(p[:-1, 2])
    dx, dz = np.diff(p[:, 0]), np.diff(p[:, 1])
    fwd, side = c * dx + s * dz, -s * dx + c * dz              # true motion in the robot's frame
    d = np.hypot(fwd, side)
    turn = np.angle(np.exp(1j * np.diff(p[:, 2])))
    k = 1.0 + scale_error + slip * e / np.sqrt(np.maximum(d, 1e-12))
    k = np.where(d > 0, k, 1.0)
    turn_read = turn + heading_bias * d + heading_noise * np.sqrt(d) * h
    out = np.empty_like(p)
    out[0] = p[0]
    yaw = p[0, 2] + np.concatenate([[0.0], np.cumsum(turn_read)])
    cy, sy = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    out[1:, 0] = p[0, 0] + np.cumsum(k * (cy * fwd - sy * side))
    out[1:, 1] = p[0, 1] + np.cumsum(k * (sy * fwd + cy * side))
    out[:, 2] = yaw
    return out
