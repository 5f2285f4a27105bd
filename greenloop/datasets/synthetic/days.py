"""The greenhouse over days: a larger hall (``DaysHall``), what changes from day to day (``Day``),
the days' design (``design_days``) and each day's route (``day_route``).

The hall frame is the single-day hall's (see ``hall``: x across, y up, z along the beds, metres,
origin at a floor corner), with ``n_aisles`` aisles between ``n_aisles + 1`` beds, a cross aisle
in front of (``front_z``) and behind (``back_z``) the beds and a corridor along each side wall
(``side_x``), through which the robot goes from one end of the hall to the other. A day's route
drives its aisles in its order, each in its direction (+1: from the front towards the back, +z;
-1: the other way), as a rounded polyline sampled every ``spacing`` metres.

What a ``Day`` changes: the light (sun from an azimuth / elevation, overcast, or night under the
LED bars), the growth stage of the plants (size, leaf count, colour), which beds are harvested
(empty holes), where the carts and crates stand, and the route. The layout never changes.

Ground truth across days is the one pose rule (``groundtruth.for_sequence`` on the stream: Qi 2024
Eq. 5 < 0.5 with the stream's ``exclude``), which admits at most 20.4 degrees between two views
(at zero distance), so an aisle driven the other way on another day is never a loop by it,
however close the cameras; ``groundtruth.relative_poses`` gives the true relative pose of any
pair, opposite ones included, to score a closure's estimated pose.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from greenloop.datasets.synthetic.hall import _check_seed, BED_WIDTH
from greenloop.datasets.synthetic.route import _filleted_path, _path_poses, TURN_RADIUS

LIGHTS = ("sun", "overcast", "night")
CROPS = ("green", "red", "oak", "red_oak")   # lettuce varieties, keys of plants.PLANT_KINDS
OBJECT_KINDS = ("cart", "crates")


@dataclass(frozen=True)
class DaysHall:
    """The larger hall: ``n_aisles`` (>= 1) aisles between beds ``bed_length`` metres long.

    Every length in metres (beds ``hall.BED_WIDTH`` wide, as in the single-day hall); the derived
    layout is in the properties (hall frame, see module doc).
    """
    n_aisles: int = 6
    bed_length: float = 12.0
    bed_pitch: float = 2.0
    side: float = 1.5             # side corridor: wall to the first bed's edge
    front: float = 4.0            # front cross aisle: front wall to the beds
    back: float = 3.8             # back cross aisle: beds to the back wall
    height: float = 4.2

    def __post_init__(self):
        if isinstance(self.n_aisles, bool) or int(self.n_aisles) != self.n_aisles or self.n_aisles < 1:
            raise ValueError(f"n_aisles must be an integer >= 1, got {self.n_aisles!r}")
        if not (self.bed_length >= 2.0 and self.bed_pitch >= 1.9 and self.side >= 1.2 and self.front >= 3.5
                and self.back >= 3.0 and self.height >= 3.0):
            raise ValueError(f"hall too small for the route's turns and the fixtures: {self}; use bed_length >= 2, "
                             f"bed_pitch >= 1.9, side >= 1.2, front >= 3.5, back >= 3, height >= 3 metres")

    @property
    def bed_x(self) -> np.ndarray:
        """(n_aisles + 1,) x of the beds' centre lines."""
        return self.side + BED_WIDTH / 2 + self.bed_pitch * np.arange(self.n_aisles + 1)

    @property
    def aisle_x(self) -> np.ndarray:
        """(n_aisles,) x of the aisles' centre lines (between neighbouring beds)."""
        return self.bed_x[:-1] + self.bed_pitch / 2

    @property
    def width(self) -> float:
        return float(2 * self.side + self.bed_pitch * self.n_aisles + BED_WIDTH)

    @property
    def bed_z0(self) -> float:
        return float(self.front)

    @property
    def depth(self) -> float:
        return float(self.front + self.bed_length + self.back)

    @property
    def front_z(self) -> float:
        """z of the route's line in the front cross aisle."""
        return float(self.front - 2.2)

    @property
    def back_z(self) -> float:
        """z of the route's line in the back cross aisle."""
        return float(self.front + self.bed_length + 1.6)

    @property
    def side_x(self) -> tuple[float, float]:
        """x of the route's line in the left and the right side corridor."""
        return self.side / 2, self.width - self.side / 2

    def aisle_at(self, x, z) -> np.ndarray:
        """The aisle each point stands in: x, z (N,) metres in the hall frame. Returns (N,) int64, the
        aisle index (0 .. n_aisles - 1) where the point lies between the two beds' centre lines of that
        aisle and along the beds (bed_z0 .. bed_z0 + bed_length), else -1 (cross aisles, corridors)."""
        x, z = np.asarray(x, dtype=np.float64), np.asarray(z, dtype=np.float64)
        if x.shape != z.shape or x.ndim != 1:
            raise ValueError(f"x and z must be (N,) arrays of one length, got shapes {x.shape} and {z.shape}")
        a = np.floor((x - self.bed_x[0]) / self.bed_pitch).astype(np.int64)
        inside = (a >= 0) & (a < self.n_aisles) & (z >= self.bed_z0) & (z <= self.bed_z0 + self.bed_length)
        return np.where(inside, a, -1)


TINY_HALL = DaysHall(n_aisles=2, bed_length=3.0)


@dataclass(frozen=True)
class Day:
    """One recording day of the hall.

    name: the traversal's name (``day-00`` ...); offset_days: days since the first recording;
    light: one of LIGHTS; sun_azimuth, sun_elevation: degrees (sun only; azimuth from +z towards
    +x); growth: the plants' growth stage (0.3 young .. 1.2 overgrown; 1 = the single-day
    sequence's plants), scaling size and leaf count and paling the young; harvested: bed indices
    left as empty holes; objects: ((kind, x, z), ...) carts and crates (OBJECT_KINDS, metres);
    route: ((aisle, direction), ...) in driving order, direction +1 (towards +z) or -1.
    """
    name: str
    offset_days: int
    light: str
    growth: float
    route: tuple
    sun_azimuth: float = 0.0
    sun_elevation: float = 0.0
    harvested: tuple = ()
    objects: tuple = field(default=())


# the first five days: (offset, light, azimuth, elevation, order rule, direction rule, harvested)
_PLAN = ((0, "sun", 100.0, 25.0, "up", "serpentine", ()),
         (4, "overcast", 0.0, 0.0, "up", "last_opposite", ()),
         (8, "night", 0.0, 0.0, "down", "odd_opposite", ()),
         (13, "sun", 255.0, 12.0, "down", "serpentine", ()),
         (18, "sun", 180.0, 58.0, "interleaved", "opposite", (1, 2)))


def _order(rule: str, n: int, rng) -> list[int]:
    """Aisle order of a route rule for ``n`` aisles (``random``: a permutation drawn from rng)."""
    if rule == "up":
        return list(range(n))
    if rule == "down":
        return list(range(n - 1, -1, -1))
    if rule == "interleaved":
        return list(range(0, n, 2)) + list(range(1, n, 2))
    return [int(a) for a in rng.permutation(n)]


def _direction(rule: str, aisle: int, n: int, rng) -> int:
    """Direction (+1 / -1) of ``aisle`` under a rule; ``serpentine`` (+1 on even aisles) is day
    0's, the others flip some of its aisles (``random``: each flipped with probability 1/2)."""
    base = 1 if aisle % 2 == 0 else -1
    flip = {"serpentine": False, "last_opposite": aisle == n - 1, "odd_opposite": aisle % 2 == 1,
            "opposite": True}.get(rule)
    if flip is None:
        flip = bool(rng.random() < 0.5)
    return -base if flip else base


def design_days(n_days: int = 5, hall: DaysHall = DaysHall(), seed: int = 0) -> list[Day]:
    """The days' design: the five planned days of ``_PLAN`` (sun in the morning, overcast, night,
    low evening sun, noon after a harvest of beds 1 and 2), then seeded ones (random light, order,
    directions). Growth follows the date: 0.45 + 0.04 per day, capped at 1.2. Carts and crates
    stand at seeded places per day (``_objects``). Returns ``n_days`` (>= 1) ``Day`` records.
    """
    if isinstance(n_days, bool) or int(n_days) != n_days or n_days < 1:
        raise ValueError(f"n_days must be an integer >= 1, got {n_days!r}")
    seed = _check_seed(seed)
    days = []
    for k in range(int(n_days)):
        rng = np.random.default_rng([seed, k, 0xDA75])
        if k < len(_PLAN):
            offset, light, az, el, order, dirs, harvested = _PLAN[k]
            harvested = tuple(b for b in harvested if b <= hall.n_aisles)
        else:
            offset = _PLAN[-1][0] + 5 * (k - len(_PLAN) + 1)
            light = LIGHTS[int(rng.integers(len(LIGHTS)))]
            az, el = float(rng.uniform(60, 300)), float(rng.uniform(10, 60))
            order, dirs, harvested = "random", "random", ()
        if light != "sun":
            az, el = 0.0, 0.0
        aisles = _order(order, hall.n_aisles, rng)
        route = tuple((a, _direction(dirs, a, hall.n_aisles, rng)) for a in aisles)
        days.append(Day(f"day-{k:02d}", offset, light, min(1.2, 0.45 + 0.04 * offset), route, az, el,
                        harvested, _objects(hall, rng)))
    return days


def _objects(hall: DaysHall, rng) -> tuple:
    """Seeded carts and crates of one day, out of the route's way: a stack of crates at a bed's
    front or back end for every second aisle, a cart against the front or back wall for every
    three. Returns ((kind, x, z) metres, ...)."""
    out = []
    for _ in range(max(1, hall.n_aisles // 2)):
        b = int(rng.integers(hall.n_aisles + 1))
        z = hall.bed_z0 - 0.45 if rng.random() < 0.5 else hall.bed_z0 + hall.bed_length + 0.45
        out.append(("crates", float(hall.bed_x[b] + rng.uniform(-0.2, 0.2)), float(z)))
    for _ in range(max(1, hall.n_aisles // 3)):
        x = float(rng.uniform(hall.side + 0.5, hall.width - hall.side - 0.5))
        z = 0.55 if rng.random() < 0.5 else hall.depth - 0.55
        out.append(("cart", x, z))
    return tuple(out)


def day_waypoints(day: Day, hall: DaysHall) -> np.ndarray:
    """Corner points of the day's route, (K, 2) as (x, z) metres in the hall frame.

    It starts in the left side corridor at the front cross aisle; an aisle entered from the
    cross aisle the robot is in is reached along it, otherwise through the nearer side corridor.
    """
    if not day.route:
        raise ValueError(f"{day.name}: route is empty; give ((aisle, direction), ...)")
    left, right = hall.side_x
    pts = [(left, hall.front_z)]
    for a, d in day.route:
        if not (0 <= a < hall.n_aisles and d in (1, -1)):
            raise ValueError(f"{day.name}: route step {(a, d)!r} must be (aisle 0..{hall.n_aisles - 1}, +1 or -1)")
        xa = float(hall.aisle_x[a])
        enter, leave = (hall.front_z, hall.back_z) if d > 0 else (hall.back_z, hall.front_z)
        x, z = pts[-1]
        if z != enter:
            side = left if abs(x - left) + abs(xa - left) <= abs(x - right) + abs(xa - right) else right
            pts += [(side, z), (side, enter)]
        pts += [(xa, enter), (xa, leave)]
    keep = [pts[0]] + [p for p, q in zip(pts[1:], pts[:-1]) if p != q]
    return np.array(keep, dtype=np.float64)


def day_route(day: Day, hall: DaysHall, spacing: float, seed: int = 0, index: int = 0):
    """The day's camera poses, one every ``spacing`` metres (> 0) along its route.

    seed, index: the seed and the day's index draw its jitter and wander (as ``route_world``).
    Returns (poses (N, 4, 4) float64 camera-to-hall, OpenCV camera axes; s (N,) arc length in
    metres).
    """
    if not spacing > 0:
        raise ValueError(f"spacing must be > 0 metres between frames, got {spacing!r}")
    wp = day_waypoints(day, hall)
    length = _filleted_path(wp, TURN_RADIUS)[0][-1]
    n = max(2, int(round(length / spacing)) + 1)
    return _path_poses(wp, n, np.random.default_rng([_check_seed(seed), int(index), 0x5EED]))
