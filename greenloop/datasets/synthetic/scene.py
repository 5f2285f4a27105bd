"""The 3D greenhouse hall a frame is rendered from: ``build_scene(seed)`` -> ``Scene``.

A plant factory like the one of the real set: rows of raised cultivation beds with lettuce-like
plants, blank beds, posts, overhead pipes, LED bars, roof trusses, an irrigation gantry, a water
tank, a cabinet, fans, doors. Solid things are convex objects made of polygons (``_box``,
``_beam``, ``_prism``), shaded once by a fixed LIGHT; the plants come from ``plants``, the hall
box's floor, roof and wall textures from ``textures``. Hall frame (see ``hall``), metres,
colours BGR 0..255.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from greenloop.datasets.synthetic.hall import (AISLE_A2, AISLE_A3, BACK_AISLE_Z, BED_LENGTH,
                                               BED_TOP, BED_WIDTH, BED_X, BED_Z0, HALL_DEPTH,
                                               HALL_HEIGHT, HALL_WIDTH, _check_seed)
from greenloop.datasets.synthetic.plants import _make_plants
from greenloop.datasets.synthetic.textures import _texture_atlas

LIGHT = np.array([0.35, 1.0, 0.25]) / np.linalg.norm([0.35, 1.0, 0.25])
FOG_COLOR = np.array([205, 210, 205], np.float32)   # BGR of the haze (render: distance fog)


@dataclass
class Scene:
    """Everything a frame needs; hall frame (x across, y up, z along), metres, colours BGR 0..255.

    quads (Q, 4, 3) polygon corners; quad_color (Q, 3) shaded colour; quad_normal (Q, 3) outward
    unit normals; quad_obj (Q,) object index; obj_lo / obj_hi (O, 3) object bounding boxes;
    obj_far (O,) draw order key: True = farthest corner (beds: drawn before what stands on them),
    False = nearest point. leaf_center / leaf_a1 / leaf_a2 (L, 3) leaf ellipse centre and
    semi-axis vectors; leaf_color (L, 3); plant_center (P, 3), plant_radius (P,),
    plant_color (P, 3), plant_flat (P,) (0 = rosette, 1 = flat disc), plant_leaves (P + 1,) CSR
    offsets into the leaf arrays. atlas (Ha, Wa, 3) uint8 hall textures; atlas_rows (6,) first
    atlas row of floor, roof, left, right, front, back. light_phase (6,): phases (radians) of the lighting drift.
    hall_size (width x, height y, depth z) metres of the hall box (default: ``hall``'s hall);
    fog_color (3,) float32 BGR of the haze (darker at night in the days' hall).
    """
    quads: np.ndarray
    quad_color: np.ndarray
    quad_normal: np.ndarray
    quad_obj: np.ndarray
    obj_lo: np.ndarray
    obj_hi: np.ndarray
    obj_far: np.ndarray
    leaf_center: np.ndarray
    leaf_a1: np.ndarray
    leaf_a2: np.ndarray
    leaf_color: np.ndarray
    plant_center: np.ndarray
    plant_radius: np.ndarray
    plant_color: np.ndarray
    plant_flat: np.ndarray
    plant_leaves: np.ndarray
    atlas: np.ndarray
    atlas_rows: np.ndarray
    light_phase: np.ndarray
    hall_size: tuple = (HALL_WIDTH, HALL_HEIGHT, HALL_DEPTH)
    fog_color: np.ndarray = field(default_factory=FOG_COLOR.copy)


def _new_builder() -> dict:
    """Empty scene accumulator: lists of polygons, colours, object ids and object boxes."""
    return {"quads": [], "color": [], "obj": [], "lo": [], "hi": [], "far": [], "emit": []}


def _add_object(sb: dict, quads, color, far=False, emissive=False) -> None:
    """Append a convex object given as a list of (k<=4, 3) polygons (triangles padded)."""
    quads = [np.asarray(q, dtype=np.float64) for q in quads]
    quads = [np.vstack([q, q[-1:]]) if len(q) == 3 else q for q in quads]
    allv = np.concatenate(quads)
    oid = len(sb["lo"])
    sb["lo"].append(allv.min(0))
    sb["hi"].append(allv.max(0))
    sb["far"].append(far)
    for q in quads:
        sb["quads"].append(q)
        sb["color"].append(color)
        sb["obj"].append(oid)
        sb["emit"].append(emissive)


def _box(sb, lo, hi, color, far=False, emissive=False) -> None:
    """Axis-aligned box from corner ``lo`` to ``hi`` (x, y, z metres)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    c = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
    faces = [(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (3, 2, 6, 7), (0, 3, 7, 4), (1, 2, 6, 5)]
    _add_object(sb, [c[list(f)] for f in faces], color, far, emissive)


def _beam(sb, p0, p1, width, color, sides=4, emissive=False) -> None:
    """Prism of ``sides`` faces and across-size ``width`` between 3D points p0 and p1."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    ax = p1 - p0
    ax /= np.linalg.norm(ax)
    ref = np.array([0.0, 1.0, 0.0]) if abs(ax[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(ax, ref)
    u /= np.linalg.norm(u)
    v = np.cross(ax, u)
    ang = np.pi / sides + 2 * np.pi * np.arange(sides) / sides
    r = width / 2 / np.cos(np.pi / sides)
    ring = r * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v)
    quads = [np.array([p0 + ring[i], p0 + ring[(i + 1) % sides], p1 + ring[(i + 1) % sides],
                       p1 + ring[i]]) for i in range(sides)]
    _add_object(sb, quads, color, False, emissive)


def _prism(sb, cx, cz, radius, y0, y1, color, sides=16) -> None:
    """Vertical cylinder (``sides``-gon prism) with a top, centre (cx, cz), floor-standing."""
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = np.stack([cx + radius * np.cos(ang), np.zeros(sides), cz + radius * np.sin(ang)], 1)
    lo, hi = ring + [0, y0, 0], ring + [0, y1, 0]
    quads = [np.array([lo[i], lo[(i + 1) % sides], hi[(i + 1) % sides], hi[i]])
             for i in range(sides)]
    for i in range(1, sides - 1, 2):   # top as a fan of quads (last may be a triangle)
        quads.append(hi[[0, i, i + 1, min(i + 2, sides - 1)]])
    _add_object(sb, quads, color)


def build_scene(seed: int = 0) -> Scene:
    """Build the greenhouse hall for ``seed`` (plant sizes/colours, textures, lighting drift).

    The layout (beds, aisles, equipment) is fixed; the seed varies the details. Returns a
    ``Scene``.
    """
    seed = _check_seed(seed)
    rng = np.random.default_rng([seed, 0x5CE4E])
    sb = _new_builder()
    _add_beds(sb)
    truss_z = np.arange(3.0, HALL_DEPTH - 0.5, 3.0)
    _add_posts(sb, truss_z)
    _add_roof_structure(sb, truss_z)
    _add_pipes_and_lights(sb)
    _add_gantry(sb)
    _add_equipment(sb)
    # the random draws below keep their order: quad colours, plants, textures, lighting phases
    quads, n, color, obj, lo, hi = _finish_quads(sb, rng)
    plants = _make_plants(rng)
    atlas, rows = _texture_atlas(rng)
    return Scene(quads=quads, quad_color=color.astype(np.float32), quad_normal=n, quad_obj=obj,
                 obj_lo=lo, obj_hi=hi, obj_far=np.asarray(sb["far"]),
                 plant_center=plants[0], plant_radius=plants[1], plant_color=plants[2],
                 plant_flat=plants[3], plant_leaves=plants[4], leaf_center=plants[5],
                 leaf_a1=plants[6], leaf_a2=plants[7], leaf_color=plants[8],
                 atlas=atlas, atlas_rows=np.asarray(rows, np.float32),
                 light_phase=rng.uniform(0, 2 * np.pi, 6))


def _add_beds(sb: dict) -> None:
    """The six cultivation beds of the hall (``_add_bed``). Draws no random numbers."""
    tops = [(215, 220, 218), (60, 72, 88), (218, 222, 220), (215, 220, 218), (60, 72, 88),
            (210, 215, 215)]
    for k, xc in enumerate(BED_X):
        _add_bed(sb, xc, BED_Z0, BED_LENGTH, tops[k])


def _add_bed(sb: dict, xc: float, z0: float, length: float, top_color) -> None:
    """One cultivation bed (tray, growing surface of ``top_color`` BGR, stand) centred on x = xc
    from z0 to z0 + length (metres), split into 1 m modules along z so the painter's order stays
    right. Draws no random numbers."""
    edges = np.linspace(z0, z0 + length, int(round(length)) + 1)
    for z0, z1 in zip(edges[:-1], edges[1:]):
        _box(sb, (xc - BED_WIDTH / 2, BED_TOP - 0.13, z0), (xc + BED_WIDTH / 2, BED_TOP, z1),
             (200, 202, 200), far=True)
        # the growing surface, a hair above the tray
        top = np.array([[xc - BED_WIDTH / 2 + 0.04, BED_TOP + 0.001, z0],
                        [xc + BED_WIDTH / 2 - 0.04, BED_TOP + 0.001, z0],
                        [xc + BED_WIDTH / 2 - 0.04, BED_TOP + 0.001, z1],
                        [xc - BED_WIDTH / 2 + 0.04, BED_TOP + 0.001, z1]])
        _add_object(sb, [top], top_color, far=True)
        _box(sb, (xc - BED_WIDTH / 2 + 0.1, 0.0, z0), (xc + BED_WIDTH / 2 - 0.1, BED_TOP - 0.13, z1),
             (62, 64, 66), far=True)


def _add_posts(sb: dict, truss_z: np.ndarray) -> None:
    """Posts along the walls and through every other bed, on the truss lines ``truss_z`` (T,)
    (z metres)."""
    for zt in truss_z:
        for xp in (0.12, HALL_WIDTH - 0.12) + tuple(BED_X[1::2]):
            inside_bed = BED_Z0 < zt < BED_Z0 + BED_LENGTH
            if xp in BED_X and not inside_bed:
                continue
            _box(sb, (xp - 0.05, 0.0, zt - 0.05), (xp + 0.05, HALL_HEIGHT, zt + 0.05), (190, 192, 188))


def _add_roof_structure(sb: dict, truss_z: np.ndarray) -> None:
    """Roof trusses on ``truss_z`` (T,) and at both end walls (z metres): bottom and top chords
    in 2.3 m pieces, verticals and diagonals; then the purlins along the hall."""
    W, D = HALL_WIDTH, HALL_DEPTH
    grey = (175, 177, 172)
    for zt in np.concatenate([truss_z, [0.3, D - 0.3]]):
        xs = np.linspace(0.0, W, 7)
        for x0, x1 in zip(xs[:-1], xs[1:]):
            _box(sb, (x0, 3.35, zt - 0.04), (x1, 3.43, zt + 0.04), grey)
            _box(sb, (x0, 3.97, zt - 0.04), (x1, 4.05, zt + 0.04), grey)
        xw = np.linspace(0.0, W, 11)
        for i, (x0, x1) in enumerate(zip(xw[:-1], xw[1:])):
            _beam(sb, (x0, 3.43, zt), (x0, 3.97, zt), 0.04, grey)
            a, b = ((x0, 3.43, zt), (x1, 3.97, zt)) if i % 2 == 0 else ((x0, 3.97, zt), (x1, 3.43, zt))
            _beam(sb, a, b, 0.035, grey)
    for xp in np.arange(1.2, W, 2.4):
        for z0 in np.arange(0.0, D - 0.01, 2.5):
            _box(sb, (xp - 0.03, 3.9, z0), (xp + 0.03, 3.97, min(z0 + 2.5, D)), grey)


def _add_pipes_and_lights(sb: dict) -> None:
    """Irrigation pipes over the beds, LED bars (emissive) with their housings over the beds, and
    a big air duct above aisle A2."""
    D = HALL_DEPTH
    z_lo, z_hi = 0.6, D - 0.6
    for xc in BED_X:
        for z0 in np.arange(z_lo, z_hi, 2.0):
            _beam(sb, (xc + 0.3, 2.45, z0), (xc + 0.3, 2.45, min(z0 + 2.0, z_hi)), 0.045,
                  (170, 165, 160))
        for z0 in np.arange(BED_Z0 + 0.2, BED_Z0 + BED_LENGTH - 0.5, 1.6):
            _box(sb, (xc - 0.07, 1.95, z0), (xc + 0.07, 2.0, z0 + 1.2), (235, 225, 250), emissive=True)
            _box(sb, (xc - 0.09, 2.0, z0), (xc + 0.09, 2.05, z0 + 1.2), (120, 120, 125))
    for z0 in np.arange(0.0, D - 0.01, 2.0):
        _beam(sb, (AISLE_A2, 3.0, z0), (AISLE_A2, 3.0, min(z0 + 2.0, D)), 0.45, (225, 228, 230), sides=8)


def _add_gantry(sb: dict) -> None:
    """The automated irrigation gantry across the beds, on rails along the walls, with its
    carriage and nozzles."""
    W = HALL_WIDTH
    zg = BED_Z0 + 0.55 * BED_LENGTH
    orange = (30, 135, 235)
    xs = np.linspace(0.35, W - 0.35, 7)
    for x0, x1 in zip(xs[:-1], xs[1:]):
        _box(sb, (x0, 2.1, zg - 0.12), (x1, 2.35, zg + 0.12), orange)
        _beam(sb, (x0, 1.7, zg), (x1, 1.7, zg), 0.04, (90, 90, 95))
    for xl in (0.35, W - 0.35):
        _box(sb, (xl - 0.08, 0.0, zg - 0.15), (xl + 0.08, 2.35, zg + 0.15), orange)
    _box(sb, (AISLE_A3 - 0.9, 1.85, zg - 0.2), (AISLE_A3 - 0.4, 2.1, zg + 0.2), (80, 80, 85))
    for xn in np.arange(0.8, W - 0.5, 0.5):
        _beam(sb, (xn, 1.7, zg), (xn, 1.55, zg), 0.03, (40, 40, 40))


def _add_equipment(sb: dict) -> None:
    """Front area: water tank, electrical cabinet, crates; back area: dosing unit with canisters,
    a cart with plant trays; a robot in the aisle between the last two beds."""
    D = HALL_DEPTH
    _prism(sb, 11.9, 1.15, 0.6, 0.0, 1.7, (170, 115, 45))
    _box(sb, (1.0, 0.0, 0.02), (2.0, 1.9, 0.5), (175, 182, 186))
    _box(sb, (1.05, 0.15, 0.5), (1.48, 1.8, 0.52), (150, 158, 162))
    _box(sb, (1.52, 0.15, 0.5), (1.95, 1.8, 0.52), (150, 158, 162))
    for i in range(3):
        for j in range(2):
            _box(sb, (10.0 + 0.62 * j, 0.3 * i, 0.3), (10.55 + 0.62 * j, 0.3 * i + 0.28, 0.7),
                 (40, 40, 190) if (i + j) % 2 else (30, 60, 200))
    _box(sb, (9.4, 0.0, D - 0.75), (11.0, 1.35, D - 0.02), (228, 228, 226))
    for i, col in enumerate([(40, 40, 200), (200, 90, 30), (40, 160, 40)]):
        _prism(sb, 9.75 + 0.5 * i, D - 0.4, 0.17, 1.35, 1.85, col, sides=10)
    _box(sb, (1.6, 0.15, BACK_AISLE_Z - 0.2), (2.9, 0.85, BACK_AISLE_Z + 0.5), (60, 110, 150))
    for i in range(3):
        _box(sb, (1.7 + 0.4 * i, 0.85, BACK_AISLE_Z - 0.1), (2.05 + 0.4 * i, 1.15, BACK_AISLE_Z + 0.4),
             (50, 150, 60))
    _box(sb, (10.5, 0.05, BED_Z0 + 2.0), (11.1, 1.25, BED_Z0 + 2.8), (30, 200, 235))
    _box(sb, (10.55, 1.25, BED_Z0 + 2.1), (11.05, 1.3, BED_Z0 + 2.7), (40, 40, 40))


def _finish_quads(sb: dict, rng, light: np.ndarray = LIGHT):
    """Stack the builder's polygons, orient their normals outwards and shade them.

    Returns (quads (Q, 4, 3) float64 metres, normals (Q, 3) outward unit vectors, colour (Q, 3)
    float64 BGR 0..255 after Lambert shading by the unit direction ``light`` (3,) towards the
    light (emissive quads unshaded) and a seeded +-4 %
    brightness per quad, obj (Q,) object index, lo / hi (O, 3) object bounding boxes in metres).
    Draws Q uniforms from ``rng``.
    """
    quads = np.stack(sb["quads"]).astype(np.float64)
    obj = np.asarray(sb["obj"])
    lo, hi = np.stack(sb["lo"]), np.stack(sb["hi"])
    centre = (lo + hi)[obj] / 2
    n = np.cross(quads[:, 1] - quads[:, 0], quads[:, 3] - quads[:, 0])
    bad = np.linalg.norm(n, axis=1) < 1e-12
    n[bad] = np.cross(quads[bad, 1] - quads[bad, 0], quads[bad, 2] - quads[bad, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    flip = np.einsum("ij,ij->i", n, quads.mean(1) - centre) < 0
    n[flip] *= -1
    color = np.asarray(sb["color"], np.float64)
    emit = np.asarray(sb["emit"])
    shade = 0.5 + 0.55 * np.clip(n @ light, 0, None)
    color = np.where(emit[:, None], color, color * shade[:, None])
    color = np.clip(color * rng.uniform(0.96, 1.04, (len(color), 1)), 0, 255)
    return quads, n, color, obj, lo, hi
