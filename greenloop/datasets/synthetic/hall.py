"""The hall frame and the hall's fixed layout, shared by the route, the scene and the renderer.

Coordinates: the hall ("world") frame has x across the hall, y up, z along the beds, in metres,
origin at a floor corner. Files use the first camera's frame, as ORB-SLAM writes them.

Six raised cultivation beds run along z, their centre lines at BED_X; the route drives aisles A1,
A2 and A3 between them and the cross aisles in front of (FRONT_AISLE_Z) and behind
(BACK_AISLE_Z) them. The seed varies the details (plants, textures, lighting, route jitter),
never this layout; ``_check_seed`` is the one check of it for every part.
"""
from __future__ import annotations

# metres, in the hall frame
HALL_WIDTH = 13.6         # x extent
HALL_HEIGHT = 4.2         # y of the roof plane (ceiling of the ray-cast box)
BED_PITCH = 2.0
BED_WIDTH = 1.1
BED_TOP = 0.62
BED_X = tuple(1.8 + BED_PITCH * k for k in range(6))   # bed centre lines
BED_Z0 = 4.0
BED_LENGTH = 8.5
FRONT_AISLE_Z = 1.8       # cross aisle in front of the beds (route line)
BACK_AISLE_Z = BED_Z0 + BED_LENGTH + 1.4
HALL_DEPTH = BACK_AISLE_Z + 2.4
AISLE_A1, AISLE_A2, AISLE_A3 = 4.8, 6.8, 8.8


def _check_seed(seed) -> int:
    """``seed`` as an int, or ValueError unless it is a non-negative integer."""
    if isinstance(seed, bool) or int(seed) != seed or int(seed) < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)
