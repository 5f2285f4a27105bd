"""The hall's textures: concrete floor, glazed roof and four walls, stacked into one atlas.

Each texture is a BGR uint8 image of TEX_RES metres per texel, drawn with OpenCV over seeded
smooth noise: the floor with its joints, drain, safety lines, hose, puddle and leaves; the roof
with glazing bars and a shade screen; the walls with panels, vegetation outside, a cooling pad,
a vent, doors, signs and exhaust fans. The renderer ray-casts the hall box and looks its pixels
up in the atlas (``render._render_hall``).
"""
from __future__ import annotations

import cv2
import numpy as np

from greenloop.datasets.synthetic.hall import (BACK_AISLE_Z, BED_LENGTH, BED_WIDTH, BED_X, BED_Z0,
                                               HALL_DEPTH, HALL_HEIGHT, HALL_WIDTH)

TEX_RES = 0.02            # metres per texel of the hall textures


def _smooth_noise(rng, shape, cell) -> np.ndarray:
    """Smooth random field of ``shape`` (rows, cols), feature size ~``cell`` texels, std ~1."""
    h, w = shape
    gh, gw = max(2, int(h / cell) + 2), max(2, int(w / cell) + 2)
    g = rng.standard_normal((gh, gw)).astype(np.float32)
    big = cv2.resize(g, (int(gw * cell), int(gh * cell)), interpolation=cv2.INTER_CUBIC)
    out = big[:h, :w]
    return out / max(float(out.std()), 1e-6)


def _texture_floor(rng) -> np.ndarray:
    """Concrete floor texture (rows = z, cols = x, TEX_RES m per texel), BGR uint8 (Hz, Wx, 3)."""
    s = 1.0 / TEX_RES
    h, w = int(round(HALL_DEPTH * s)), int(round(HALL_WIDTH * s))
    base = np.array([112, 117, 120], np.float32)
    n = 14 * _smooth_noise(rng, (h, w), 60) + 8 * _smooth_noise(rng, (h, w), 14)
    tex = base[None, None] + n[..., None] * np.array([1.0, 1.0, 0.95], np.float32)
    shade = np.ones((h, w), np.float32)
    for xc in BED_X:   # damp, darker floor around and under the beds (algae, shadow)
        x0, x1 = int((xc - BED_WIDTH / 2 - 0.12) * s), int((xc + BED_WIDTH / 2 + 0.12) * s)
        z0, z1 = int((BED_Z0 - 0.1) * s), int((BED_Z0 + BED_LENGTH + 0.1) * s)
        shade[z0:z1, x0:x1] = 0.55
    shade = cv2.GaussianBlur(shade, (0, 0), 6)
    tex *= shade[..., None]
    greenish = np.clip(1.0 - shade, 0, 1)[..., None] * np.array([-10, 8, -8], np.float32)
    tex += greenish
    # sunlit patches from the roof glazing
    sun = np.clip(_smooth_noise(rng, (h, w), 90) - 0.9, 0, None)
    tex *= (1.0 + 0.35 * np.minimum(sun, 1.2))[..., None]
    tex = np.clip(tex, 0, 255).astype(np.uint8)
    # expansion joints across the hall every 2.5 m, a drain grate in front, safety lines
    for zj in np.arange(2.5, HALL_DEPTH, 2.5):
        cv2.line(tex, (0, int(zj * s)), (w, int(zj * s)), (70, 72, 74), 2, cv2.LINE_AA)
    zg = int(0.9 * s)
    cv2.rectangle(tex, (int(2.5 * s), zg - 8), (int(11.0 * s), zg + 8), (60, 62, 64), -1)
    for xg in range(int(2.5 * s), int(11.0 * s), 5):
        cv2.line(tex, (xg, zg - 8), (xg, zg + 8), (110, 112, 115), 1)
    for z_line in (0.45, HALL_DEPTH - 0.5):
        cv2.line(tex, (int(0.3 * s), int(z_line * s)), (int((HALL_WIDTH - 0.3) * s), int(z_line * s)),
                 (40, 190, 215), 5, cv2.LINE_AA)
    # a garden hose lying in the back cross aisle, a puddle in the front one
    t = np.linspace(0, 1, 60)
    hx = (2.2 + 3.5 * t + 0.25 * np.sin(9 * t)) * s
    hz = (BACK_AISLE_Z + 0.55 + 0.3 * np.sin(5 * t + 1)) * s
    cv2.polylines(tex, [np.stack([hx, hz], 1).astype(np.int32)], False, (40, 120, 30), 3, cv2.LINE_AA)
    cv2.ellipse(tex, (int(10.2 * s), int(2.6 * s)), (int(0.7 * s), int(0.35 * s)), 10, 0, 360,
                (85, 82, 78), -1, cv2.LINE_AA)
    # fallen leaves and debris
    for _ in range(500):
        x, z = rng.uniform(0, w), rng.uniform(0, h)
        col = (40, int(rng.uniform(90, 150)), 60) if rng.random() < 0.6 else (60, 80, 100)
        cv2.circle(tex, (int(x), int(z)), int(rng.integers(1, 3)), col, -1)
    return cv2.GaussianBlur(tex, (0, 0), 0.8)


def _texture_roof(rng) -> np.ndarray:
    """Glazed roof with glazing bars and a shade screen (rows = z, cols = x), BGR uint8."""
    s = 1.0 / TEX_RES
    h, w = int(round(HALL_DEPTH * s)), int(round(HALL_WIDTH * s))
    tex = np.full((h, w, 3), (238, 240, 236), np.float32)
    tex += 6 * _smooth_noise(rng, (h, w), 50)[..., None]
    # a shade screen pulled over part of the roof
    tex[int(6.0 * s):int(11.0 * s), int(1.0 * s):int(7.5 * s)] *= np.array([0.86, 0.88, 0.9])
    tex = np.clip(tex, 0, 255).astype(np.uint8)
    for x in np.arange(0.0, HALL_WIDTH, 0.8):
        cv2.line(tex, (int(x * s), 0), (int(x * s), h), (150, 152, 150), 3)
    for z in np.arange(0.0, HALL_DEPTH, 2.5):
        cv2.line(tex, (0, int(z * s)), (w, int(z * s)), (140, 142, 140), 4)
    return cv2.GaussianBlur(tex, (0, 0), 1.0)


def _wall_base(rng, length: float, outside_seed_scale: float) -> np.ndarray:
    """Greenhouse wall: concrete knee wall, translucent panels, mullions. Rows from the top."""
    s = 1.0 / TEX_RES
    h, w = int(round(HALL_HEIGHT * s)), int(round(length * s))
    tex = np.full((h, w, 3), (222, 226, 220), np.float32)
    # vegetation outside seen through the panels: soft dark green blobs low on the wall
    veg = np.clip(_smooth_noise(rng, (h, w), outside_seed_scale) * 0.8 + 0.2, 0, None)
    rows = np.linspace(HALL_HEIGHT, 0, h)[:, None]
    veg *= np.clip((2.6 - rows) / 1.4, 0, 1)
    tex -= (veg[..., None] * np.array([70, 45, 70], np.float32))
    tex += 5 * _smooth_noise(rng, (h, w), 20)[..., None]
    knee = int((HALL_HEIGHT - 0.8) * s)
    tex[knee:] = 150 + 8 * _smooth_noise(rng, (h - knee, w), 10)[..., None]
    tex = np.clip(tex, 0, 255).astype(np.uint8)
    for x in np.arange(0.0, length, 1.25):
        cv2.line(tex, (int(x * s), 0), (int(x * s), knee), (140, 142, 138), 4)
    for y in (2.2, 3.4):
        r = int((HALL_HEIGHT - y) * s)
        cv2.line(tex, (0, r), (w, r), (135, 137, 133), 5)
    for y in (0.3, 0.5):   # heating pipes along the wall
        r = int((HALL_HEIGHT - y) * s)
        cv2.line(tex, (0, r), (w, r), (228, 230, 230), 4)
        cv2.line(tex, (0, r + 3), (w, r + 3), (120, 120, 120), 1)
    return tex


def _fan(tex, xc: float, hub: bool = True) -> None:
    """Draw an exhaust fan centred xc metres along a wall texture, 1.9 m up: its housing, blades and
    (``hub``) its hub."""
    s = 1.0 / TEX_RES
    c = (int(xc * s), int(tex.shape[0] - 1.9 * s))
    cv2.rectangle(tex, (c[0] - 32, c[1] - 32), (c[0] + 32, c[1] + 32), (185, 188, 190), -1)
    cv2.circle(tex, c, 29, (45, 48, 50), -1)
    for a in np.arange(0, 360, 15):
        e = (int(c[0] + 29 * np.cos(np.radians(a))), int(c[1] + 29 * np.sin(np.radians(a))))
        cv2.line(tex, c, e, (150, 150, 150), 1, cv2.LINE_AA)
    if hub:
        cv2.circle(tex, c, 5, (170, 170, 170), -1)


def _rect(tex, x0, y0, x1, y1, color, border=None):
    """Fill a wall rectangle given in metres (x along the wall, y = height above the floor)."""
    s = 1.0 / TEX_RES
    h = tex.shape[0]
    p0 = (int(x0 * s), int(h - y1 * s))
    p1 = (int(x1 * s), int(h - y0 * s))
    cv2.rectangle(tex, p0, p1, color, -1)
    if border is not None:
        cv2.rectangle(tex, p0, p1, border, 3)


def _texture_walls(rng) -> list[np.ndarray]:
    """Left (x=0), right (x=W), front (z=0) and back (z=D) wall textures, rows from the top."""
    s = 1.0 / TEX_RES
    left = _wall_base(rng, HALL_DEPTH, 70)
    right = _wall_base(rng, HALL_DEPTH, 45)
    front = _wall_base(rng, HALL_WIDTH, 55)
    back = _wall_base(rng, HALL_WIDTH, 80)
    # left wall: a wet cooling pad, an electrical box with signs, a hose reel
    _rect(left, 6.0, 0.8, 11.0, 2.0, (70, 125, 165))
    for x in np.arange(6.0, 11.0, 0.06):
        cv2.line(left, (int(x * s), int(left.shape[0] - 2.0 * s)),
                 (int((x + 0.05) * s), int(left.shape[0] - 0.8 * s)), (55, 100, 140), 1)
    _rect(left, 2.4, 1.1, 3.2, 2.0, (205, 205, 200), (90, 90, 90))
    _rect(left, 2.55, 1.6, 3.05, 1.8, (40, 200, 230))
    cv2.circle(left, (int(13.0 * s), int(left.shape[0] - 1.2 * s)), int(0.35 * s), (40, 140, 60), -1)
    cv2.circle(left, (int(13.0 * s), int(left.shape[0] - 1.2 * s)), int(0.1 * s), (60, 60, 60), -1)
    # right wall: a roll-up vent open to the sky and trees, a fire extinguisher, a poster
    _rect(right, 3.5, 1.2, 9.5, 2.1, (225, 200, 170))
    vent = right[int(right.shape[0] - 2.1 * s):int(right.shape[0] - 1.2 * s), int(3.5 * s):int(9.5 * s)]
    trees = np.clip(_smooth_noise(rng, vent.shape[:2], 12), -1, 2)
    mask = (trees > 0.1)[..., None]
    vent[:] = np.where(mask, np.array([50, 105, 60], np.uint8), vent)
    _rect(right, 3.5, 2.1, 9.5, 2.25, (90, 95, 100))
    _rect(right, 12.2, 0.9, 12.45, 1.5, (30, 30, 200))
    _rect(right, 1.0, 1.3, 1.9, 2.3, (160, 90, 30), (240, 240, 240))
    # front wall: a big sliding door with an exit sign, a control panel
    _rect(front, 5.9, 0.0, 8.7, 2.7, (118, 104, 92), (70, 65, 60))
    for y in np.arange(0.2, 2.7, 0.3):
        _rect(front, 6.0, y, 8.6, y + 0.04, (95, 85, 75))
    _rect(front, 7.25, 0.0, 7.35, 2.7, (60, 58, 56))
    _rect(front, 6.3, 1.5, 7.0, 2.2, (200, 190, 170), (60, 60, 60))
    _rect(front, 6.9, 2.85, 7.7, 3.1, (60, 170, 40))
    _rect(front, 9.8, 1.1, 10.6, 1.9, (230, 232, 232), (100, 100, 100))
    for i, col in enumerate([(40, 40, 220), (40, 200, 40), (40, 200, 230)]):
        cv2.circle(front, (int((9.95 + 0.15 * i) * s), int(front.shape[0] - 1.7 * s)), 3, col, -1)
    # back wall: three exhaust fans, a door
    for xc in (2.6, 7.0, 11.4):
        _fan(back, xc)
    _rect(back, 4.3, 0.0, 5.3, 2.1, (80, 120, 60), (50, 60, 50))
    return [cv2.GaussianBlur(t, (0, 0), 0.8) for t in (left, right, front, back)]


def _texture_atlas(rng):
    """Floor, roof and the four wall textures stacked into one atlas, each followed by two rows
    repeating its last row (so bilinear lookups never bleed into the next texture).

    Returns (atlas (Ha, Wa, 3) uint8 BGR, rows (6,) int first atlas row of floor, roof, left,
    right, front, back). Draws the textures' random numbers from ``rng`` in that order.
    """
    floor, roof = _texture_floor(rng), _texture_roof(rng)
    walls = _texture_walls(rng)
    return _stack_atlas([floor, roof] + walls)


def _stack_atlas(faces):
    """Stack the six face textures (floor, roof, left, right, front, back; BGR uint8) into one
    atlas as ``_texture_atlas`` returns it: (atlas (Ha, Wa, 3) uint8, rows (6,) first rows)."""
    width = max(t.shape[1] for t in faces)
    rows = np.cumsum([0] + [t.shape[0] + 2 for t in faces])[:-1]
    atlas = np.zeros((rows[-1] + faces[-1].shape[0] + 2, width, 3), np.uint8)
    for r, t in zip(rows, faces):
        atlas[r:r + t.shape[0], :t.shape[1]] = t
        atlas[r + t.shape[0]:r + t.shape[0] + 2, :t.shape[1]] = t[-1:]
    return atlas, rows
