"""The days' hall on one day: ``build_day_scene(day, hall, seed)`` -> ``scene.Scene``.

The same parts as the single-day hall (``scene``'s boxes, beams and prisms, ``plants``'
rosettes, ``textures``' noise and walls), laid out for a ``days.DaysHall``: beds of four lettuce
varieties (``days.CROPS``, one per bed), posts and roof chords, LED bars and irrigation pipes over
every bed, a portal frame at both ends of every aisle and, on the end walls, a door (front) and an
exhaust fan (back) centred on every second bed, so each is shared by the two aisles beside it and
neighbouring aisles' entrances look alike. A water tank, a cabinet and a dosing unit stand in
three corners. The day sets the light, the plants' growth, the harvested beds and the carts and
crates (``days.Day``). Everything but the day's changes is drawn from the same seeded numbers
every day, so a plant stays the same plant from day to day.

What it models and what it does not: ``MODELLED`` and ``NOT_MODELLED`` (notebook 00 prints them;
the light is one Lambert direction per day, a gain and a tint).
"""
from __future__ import annotations

import cv2
import numpy as np

from greenloop.datasets.synthetic.days import CROPS, Day, DaysHall
from greenloop.datasets.synthetic.hall import _check_seed, BED_TOP
from greenloop.datasets.synthetic.plants import _hole, _pack_plants, _rosette
from greenloop.datasets.synthetic.scene import (_add_bed, _box, _finish_quads, _new_builder, _prism,
                                                FOG_COLOR, Scene)
from greenloop.datasets.synthetic.textures import _fan, _rect, _smooth_noise, _stack_atlas, _wall_base, TEX_RES

# What the days' renderer models and what it does not: notebook 00 and the README read these, so the
# claim is written once, here, beside the code that makes it true.
MODELLED = ("one fixed layout: beds of four lettuce varieties, posts, roof chords, LED bars, irrigation pipes, "
            "portal frames, doors and fans shared by neighbouring aisles, a tank, a cabinet and a dosing unit",
            "one light per day: sun from an azimuth and elevation, overcast, or night under the LED bars, each a "
            "Lambert direction, a gain and a tint (with sensor.py's brightness drift and exposure flicker along the route)",
            "plant growth (size, leaf count, colour) and harvested beds (empty holes), the same plants every day",
            "carts and crates moved from day to day",
            "each day's route: its aisle order and each aisle's direction",
            "a mild Gaussian lens blur and D435i-like depth (quantised disparity, no reading beyond 10 m)")
NOT_MODELLED = ("shadows", "the sun's direct beams and the sky through the roof", "wind (the plants never move)",
                "motion blur", "rolling shutter", "dust or condensation", "people or other moving objects",
                "per-pixel sensor noise (0 in the days' frames)")

BED_TOPS = ((215, 220, 218), (60, 72, 88), (210, 215, 215))   # growing surfaces, BGR, by bed
GREY = (180, 182, 178)


def build_day_scene(day: Day, hall: DaysHall = DaysHall(), seed: int = 0) -> Scene:
    """The hall of ``day`` for ``seed``: hall frame, metres, colours BGR 0..255 (``Scene``).

    The quads' seeded brightness, the plants and the textures are the same every day; the light
    (``day_light``) shades and tints them, the growth and harvest change the plants, and the
    day's carts and crates stand where ``day.objects`` says.
    """
    seed = _check_seed(seed)
    direction, gain, plant_gain, fog, roof = day_light(day)
    sb = _new_builder()
    for k, xc in enumerate(hall.bed_x):
        _add_bed(sb, float(xc), hall.bed_z0, hall.bed_length, BED_TOPS[k % len(BED_TOPS)])
    _add_structure(sb, hall)
    _add_fixtures(sb, hall)
    for kind, x, z in day.objects:
        _add_moved_object(sb, kind, x, z)
    quads, n, color, obj, lo, hi = _finish_quads(sb, np.random.default_rng([seed, 0x5CE4E, 0xDA75]), direction)
    emit = np.asarray(sb["emit"])
    color = np.where(emit[:, None], color, np.clip(color * gain, 0, 255))
    plants = list(_day_plants(hall, day, seed))
    for i in (2, 8):   # plant and leaf colours
        plants[i] = np.clip(plants[i] * plant_gain, 0, 255).astype(np.float32)
    atlas, rows = _days_atlas(np.random.default_rng([seed, 0x7E47, 0xDA75]), hall)
    atlas = atlas.astype(np.float32) * gain.astype(np.float32)
    atlas[rows[1]:rows[2]] *= np.float32(roof)
    return Scene(quads=quads, quad_color=color.astype(np.float32), quad_normal=n, quad_obj=obj,
                 obj_lo=lo, obj_hi=hi, obj_far=np.asarray(sb["far"]),
                 plant_center=plants[0], plant_radius=plants[1], plant_color=plants[2],
                 plant_flat=plants[3], plant_leaves=plants[4], leaf_center=plants[5],
                 leaf_a1=plants[6], leaf_a2=plants[7], leaf_color=plants[8],
                 atlas=np.clip(atlas, 0, 255).astype(np.uint8), atlas_rows=np.asarray(rows, np.float32),
                 light_phase=np.random.default_rng([seed, day.offset_days, 0x11647]).uniform(0, 2 * np.pi, 6),
                 hall_size=(hall.width, hall.height, hall.depth), fog_color=fog)


def day_light(day: Day):
    """The day's light: (direction (3,) unit vector towards the light, hall frame; gain (3,) BGR
    factor of every non-emissive surface; plant_gain (3,) BGR factor of the leaves; fog (3,)
    float32 BGR haze; roof: extra factor of the glazed roof, the sky).

    sun: from ``sun_azimuth`` / ``sun_elevation`` degrees, brighter and whiter the higher it
    stands; overcast: from above, dimmer, bluish; night: the LED bars alone, from above, dark
    with a magenta tint, the plants under the bars lit more than the rest, a black sky.
    """
    if day.light == "sun":
        az, el = np.radians(day.sun_azimuth), np.radians(day.sun_elevation)
        d = np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
        s = float(np.sin(el))
        gain = (0.75 + 0.45 * s) * np.array([0.88 + 0.12 * s, 0.97 + 0.03 * s, 1.08 - 0.08 * s])
        return d, gain, gain, (FOG_COLOR * gain).astype(np.float32), 1.0
    if day.light == "overcast":
        gain = 0.8 * np.array([1.05, 1.0, 0.94])
        return np.array([0.0, 1.0, 0.0]), gain, gain, (FOG_COLOR * gain).astype(np.float32), 0.95
    if day.light == "night":
        gain = 0.16 * np.array([1.1, 0.75, 1.15])
        return (np.array([0.0, 1.0, 0.0]), gain, 0.3 * np.array([1.15, 0.7, 1.2]),
                np.array([22, 16, 26], np.float32), 0.3)
    raise ValueError(f"{day.name}: light must be sun, overcast or night, got {day.light!r}")


def _day_plants(hall: DaysHall, day: Day, seed: int):
    """The plants of every bed on ``day``: four rows every 0.25 m of bed ``k``'s crop
    (CROPS[k % 4]), 4 % missing; a harvested bed is empty holes. Each plant draws from its own
    generator (seed, bed, plant), so its shape is the same every day and only the growth
    (``day.growth``: size 0.35 + 0.65 g, leaves 0.5 + 0.5 g, paler when young) changes it.
    Returns the plant_* and leaf_* arrays of ``Scene`` (``plants._pack_plants``)."""
    g = float(day.growth)
    if not 0.05 <= g <= 2.0:
        raise ValueError(f"{day.name}: growth must be between 0.05 and 2 (1 = grown), got {g!r}")
    zs = np.arange(hall.bed_z0 + 0.18, hall.bed_z0 + hall.bed_length - 0.1, 0.25)
    rows = np.array([-0.42, -0.15, 0.15, 0.42])
    plants = []
    for k, xc in enumerate(hall.bed_x):
        crop = CROPS[k % len(CROPS)]
        for j, dx in enumerate(rows):
            for i, z in enumerate(zs + (0.125 if j % 2 else 0.0)):
                if z > hall.bed_z0 + hall.bed_length - 0.1:
                    continue
                rng = np.random.default_rng([seed, k, j, i, 0x9A47])
                x, z = xc + dx + rng.normal(0, 0.012), z + rng.normal(0, 0.012)
                if k in day.harvested or rng.random() < 0.04:
                    plants.append(_hole(x, z))
                else:
                    plants.append(_rosette(rng, np.array([x, BED_TOP, z]), crop, 0.35 + 0.65 * g,
                                           0.5 + 0.5 * g, max(0.0, 0.5 * (1 - g))))
    return _pack_plants(plants)


def _add_structure(sb: dict, hall: DaysHall) -> None:
    """Posts along the walls and on every second bed's line, roof chords across the hall, every
    3 m; an irrigation pipe and LED bars (emissive) with housings over every bed."""
    W, D, H = hall.width, hall.depth, hall.height
    for zt in np.arange(3.0, D - 0.5, 3.0):
        inside = hall.bed_z0 < zt < hall.bed_z0 + hall.bed_length
        for xp in [0.12, W - 0.12] + ([float(x) for x in hall.bed_x[1::2]] if inside else []):
            _box(sb, (xp - 0.05, 0.0, zt - 0.05), (xp + 0.05, H, zt + 0.05), GREY)
        xs = np.linspace(0.0, W, int(np.ceil(W / 2.4)) + 1)
        for x0, x1 in zip(xs[:-1], xs[1:]):
            _box(sb, (x0, 3.35, zt - 0.04), (x1, 3.43, zt + 0.04), GREY)
    for xc in hall.bed_x:
        z_lo, z_hi = 0.6, D - 0.6
        for z0 in np.arange(z_lo, z_hi, 3.0):
            _box(sb, (xc + 0.28, 2.43, z0), (xc + 0.32, 2.47, min(z0 + 3.0, z_hi)), (170, 165, 160))
        for z0 in np.arange(hall.bed_z0 + 0.2, hall.bed_z0 + hall.bed_length - 0.5, 1.6):
            _box(sb, (xc - 0.07, 1.95, z0), (xc + 0.07, 2.0, z0 + 1.2), (235, 225, 250), emissive=True)
            _box(sb, (xc - 0.09, 2.0, z0), (xc + 0.09, 2.05, z0 + 1.2), (120, 120, 125))


def _add_fixtures(sb: dict, hall: DaysHall) -> None:
    """A portal frame (two posts, a lintel, a sign) at both ends of every aisle, all alike; a
    water tank (front right), a cabinet (front left) and a dosing unit (back right)."""
    for xa in hall.aisle_x:
        for z in (hall.bed_z0 - 0.15, hall.bed_z0 + hall.bed_length + 0.15):
            for xp in (xa - 0.52, xa + 0.52):
                _box(sb, (xp - 0.04, 0.0, z - 0.04), (xp + 0.04, 2.3, z + 0.04), (90, 150, 60))
            _box(sb, (xa - 0.56, 2.3, z - 0.05), (xa + 0.56, 2.4, z + 0.05), (90, 150, 60))
            _box(sb, (xa - 0.2, 2.1, z - 0.02), (xa + 0.2, 2.28, z + 0.02), (235, 235, 235))
    W, D = hall.width, hall.depth
    _prism(sb, W - 1.6, 0.75, 0.5, 0.0, 1.7, (170, 115, 45))
    _box(sb, (1.0, 0.0, 0.02), (2.0, 1.9, 0.45), (175, 182, 186))
    _box(sb, (W - 2.6, 0.0, D - 0.7), (W - 1.1, 1.35, D - 0.02), (228, 228, 226))
    for i, col in enumerate([(40, 40, 200), (200, 90, 30), (40, 160, 40)]):
        _prism(sb, W - 2.3 + 0.5 * i, D - 0.36, 0.17, 1.35, 1.85, col, sides=10)


def _add_moved_object(sb: dict, kind: str, x: float, z: float) -> None:
    """A cart (a flat trolley with plant trays, 1.2 x 0.6 m) or a stack of crates (2 x 2 x 2)
    centred on (x, z) metres on the floor."""
    if kind == "cart":
        _box(sb, (x - 0.6, 0.15, z - 0.3), (x + 0.6, 0.75, z + 0.3), (60, 110, 150))
        for i in range(3):
            _box(sb, (x - 0.55 + 0.38 * i, 0.75, z - 0.25), (x - 0.2 + 0.38 * i, 1.0, z + 0.25), (50, 150, 60))
    elif kind == "crates":
        for i in range(2):
            for j in range(2):
                _box(sb, (x - 0.56 + 0.57 * j, 0.3 * i, z - 0.2), (x - 0.01 + 0.57 * j, 0.3 * i + 0.28, z + 0.2),
                     (40, 40, 190) if (i + j) % 2 else (30, 60, 200))
    else:
        raise ValueError(f"object kind must be cart or crates, got {kind!r}")


def _days_atlas(rng, hall: DaysHall):
    """The hall box's textures for ``hall`` (floor, roof, left, right, front, back), stacked
    (``textures._stack_atlas``): (atlas (Ha, Wa, 3) uint8 BGR, rows (6,) first rows)."""
    s = 1.0 / TEX_RES
    W, D = hall.width, hall.depth
    h, w = int(round(D * s)), int(round(W * s))
    floor = np.array([112, 117, 120], np.float32) + (14 * _smooth_noise(rng, (h, w), 60))[..., None]
    shade = np.ones((h, w), np.float32)
    for xc in hall.bed_x:
        shade[int((hall.bed_z0 - 0.1) * s):int((hall.bed_z0 + hall.bed_length + 0.1) * s),
              int((xc - 0.67) * s):int((xc + 0.67) * s)] = 0.55
    floor = np.clip(floor * cv2.GaussianBlur(shade, (0, 0), 6)[..., None], 0, 255).astype(np.uint8)
    for zj in np.arange(2.5, D, 2.5):
        cv2.line(floor, (0, int(zj * s)), (w, int(zj * s)), (70, 72, 74), 2, cv2.LINE_AA)
    for _ in range(int(W * D * 2)):
        col = (40, int(rng.uniform(90, 150)), 60) if rng.random() < 0.6 else (60, 80, 100)
        cv2.circle(floor, (int(rng.uniform(0, w)), int(rng.uniform(0, h))), int(rng.integers(1, 3)), col, -1)
    roof = np.clip(np.float32(238) + 6 * _smooth_noise(rng, (h, w), 50)[..., None], 0, 255).astype(np.uint8)
    roof = np.repeat(roof, 3, axis=2)
    for x in np.arange(0.0, W, 0.8):
        cv2.line(roof, (int(x * s), 0), (int(x * s), h), (150, 152, 150), 3)
    left, right = _wall_base(rng, D, 70), _wall_base(rng, D, 45)
    front, back = _wall_base(rng, W, 55), _wall_base(rng, W, 80)
    _rect(left, 2.4, 1.1, 3.2, 2.0, (205, 205, 200), (90, 90, 90))
    _rect(right, 1.0, 1.3, 1.9, 2.3, (160, 90, 30), (240, 240, 240))
    for xc in hall.bed_x[1::2]:   # shared by the two aisles beside bed xc
        _rect(front, xc - 0.7, 0.0, xc + 0.7, 2.5, (118, 104, 92), (70, 65, 60))
        _rect(front, xc - 0.3, 2.65, xc + 0.3, 2.85, (60, 170, 40))
        _fan(back, xc, hub=False)
    faces = [cv2.GaussianBlur(t, (0, 0), 0.8) for t in (floor, roof, left, right, front, back)]
    return _stack_atlas(faces)
