"""The plants on the beds: lettuce-like rosettes, seedlings and empty holes, as 3D leaf ellipses.

Bed by bed (``_plants_for_bed``) a fixed pattern of kinds (``PLANT_KINDS``) with seeded sizes,
colours, leaf angles and missing plants; ``_make_plants`` turns them into the plant_* and leaf_*
arrays of ``scene.Scene`` (hall frame, metres, colours BGR 0..255).
"""
from __future__ import annotations

import numpy as np

from greenloop.datasets.synthetic.hall import BED_LENGTH, BED_TOP, BED_WIDTH, BED_X, BED_Z0


def _plants_for_bed(rng, k: int, xc: float):
    """Plant list for bed ``k``: rows of (x, z, kind) with kind a key of PLANT_KINDS or 'hole'."""
    zs = np.arange(BED_Z0 + 0.18, BED_Z0 + BED_LENGTH - 0.1, 0.25)
    rows = np.array([-0.42, -0.15, 0.15, 0.42]) * (BED_WIDTH / 1.1)
    out = []
    for j, dx in enumerate(rows):
        for i, z in enumerate(zs):
            z = z + (0.125 if j % 2 else 0.0)
            if z > BED_Z0 + BED_LENGTH - 0.1:
                continue
            f = (z - BED_Z0) / BED_LENGTH
            if k == 0:
                kind = "hole"
            elif k == 1:
                kind = "green_large"
            elif k == 2:
                kind = "red" if f < 0.5 else "green"
            elif k == 3:
                kind = "seedling" if f < 0.4 else "yellow"
            elif k == 4:
                kind = "hole" if f < 0.35 else "dark"
            else:
                kind = "green" if (int(f * 7) % 3) else "yellow"
            if kind != "hole" and rng.random() < (0.04 if k != 5 else 0.12):
                kind = "hole"   # a missing plant leaves its hole
            out.append((xc + dx + rng.normal(0, 0.012), z + rng.normal(0, 0.012), kind))
    return out


# kind: (radius m, radius spread, leaves, tilt deg, outer BGR, heart BGR, leaf length, height)
PLANT_KINDS = {
    "green_large": (0.135, 0.18, 11, 28, (55, 160, 80), (95, 215, 160), 0.62, 1.0),
    "green": (0.105, 0.2, 9, 30, (60, 170, 95), (100, 220, 170), 0.6, 0.9),
    "yellow": (0.10, 0.2, 9, 32, (60, 190, 155), (110, 230, 205), 0.6, 0.9),
    "red": (0.11, 0.2, 10, 30, (70, 55, 120), (80, 160, 120), 0.6, 0.9),
    "dark": (0.12, 0.15, 8, 55, (45, 105, 50), (75, 160, 95), 0.75, 1.4),
    "seedling": (0.045, 0.25, 5, 35, (80, 190, 110), (110, 225, 170), 0.65, 0.8),
    # lettuce varieties of the days' hall (days, dayscene)
    "oak": (0.115, 0.18, 15, 33, (45, 140, 80), (90, 205, 150), 0.5, 0.85),
    "red_oak": (0.11, 0.18, 15, 33, (70, 62, 135), (85, 150, 135), 0.5, 0.85),
}


def _rosette(rng, base: np.ndarray, kind: str, scale: float = 1.0, leaf_frac: float = 1.0,
             pale: float = 0.0):
    """One rosette of ``kind`` (a key of PLANT_KINDS) standing at ``base`` (3,) metres.

    scale multiplies its radius, leaf_frac its leaf count (at least 3 leaves), pale (0..1) mixes
    its outer colour towards its heart colour (a young plant); the defaults are the grown plant of
    the single-day sequence. Returns (centre (3,) metres, radius metres, mean colour (3,) BGR,
    flat 0, leaves: a list of (centre (3,), semi-axis a1 (3,), semi-axis a2 (3,) metres,
    colour (3,) BGR 0..255)).
    """
    R0, spread, nl, tilt, outer, heart, llen, hfac = PLANT_KINDS[kind]
    R = R0 * float(np.exp(rng.normal(0, spread))) * scale
    nl = max(3, int(nl + rng.integers(-1, 2)))
    if leaf_frac != 1.0:
        nl = max(3, int(round(nl * leaf_frac)))
    tone = rng.uniform(0.85, 1.1) * np.array(outer, float)
    if pale:
        tone = (1 - pale) * tone + pale * np.array(heart, float)
    phi0 = rng.uniform(0, 2 * np.pi)
    cols, leaves = [], []
    for i in range(nl + 2):
        inner = i >= nl
        phi = phi0 + i * 2.39996 + rng.normal(0, 0.2)
        rho = R * (rng.uniform(0.05, 0.2) if inner else rng.uniform(0.35, 0.6))
        alpha = np.radians(tilt + (25 if inner else 0) + rng.normal(0, 8))
        L1 = R * llen * (0.6 if inner else 1.0) * rng.uniform(0.85, 1.15)
        L2 = L1 * rng.uniform(0.6, 0.8)
        d = np.array([np.cos(phi), 0.0, np.sin(phi)])
        p = np.array([-np.sin(phi), 0.0, np.cos(phi)])
        hgt = R * hfac * (0.25 + 0.55 * (1 - rho / R)) + np.sin(alpha) * L1 * 0.4
        mix = 0.75 if inner else rng.uniform(0.0, 0.3)
        col = (1 - mix) * tone + mix * np.array(heart, float)
        col *= rng.uniform(0.8, 1.12) * (0.85 + 0.25 * np.sin(alpha))
        leaves.append((base + rho * d + [0, hgt, 0], L1 * (np.cos(alpha) * d + [0, np.sin(alpha), 0]),
                       L2 * p, np.clip(col, 0, 255)))
        cols.append(col)
    return base + [0, R * hfac * 0.45, 0], R, np.mean(cols, 0) * 0.92, 0, leaves


def _hole(x: float, z: float):
    """An empty planting hole at (x, z) metres: a flat dark disc, as ``_rosette`` returns a plant
    (centre (3,), radius metres, colour (3,) BGR, flat 1, leaves: one (centre, a1, a2, colour)))."""
    c = np.array([x, BED_TOP + 0.003, z])
    r = 0.022
    return c, r, (58, 62, 60), 1, [(c, (r, 0, 0), (0, 0, r), (58, 62, 60))]


def _pack_plants(plants):
    """The plant_* and leaf_* arrays of ``Scene`` from a list of (centre, radius, colour, flat,
    leaves) plants (``_rosette``, ``_hole``; flat 0 = rosette, 1 = hole): float32 metres and
    BGR, plant_flat int8, plant_leaves (P + 1,) int64 CSR offsets into the leaf arrays."""
    centers, radii, colors, flats, offsets = [], [], [], [], [0]
    lc, la1, la2, lcol = [], [], [], []
    for c, r, col, flat, leaves in plants:
        for leaf in leaves:
            lc.append(leaf[0])
            la1.append(leaf[1])
            la2.append(leaf[2])
            lcol.append(leaf[3])
        centers.append(c)
        radii.append(r)
        colors.append(col)
        flats.append(flat)
        offsets.append(len(lc))
    f32 = lambda a: np.asarray(a, np.float32)   # noqa: E731
    return (f32(centers), f32(radii), f32(colors), np.asarray(flats, np.int8),
            np.asarray(offsets, np.int64), f32(lc), f32(la1), f32(la2), f32(lcol))


def _make_plants(rng):
    """Leaves of every plant. Returns the plant_* and leaf_* arrays of ``Scene`` (see there)."""
    plants = []
    for k, xc in enumerate(BED_X):
        for x, z, kind in _plants_for_bed(rng, k, xc):
            plants.append(_hole(x, z) if kind == "hole" else _rosette(rng, np.array([x, BED_TOP, z]), kind))
    return _pack_plants(plants)
