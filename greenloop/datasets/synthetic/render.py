"""One clean frame of the scene (``render_frame``): colour and depth, before the sensor model.

Rendering is a painter's algorithm with OpenCV: the hall box (floor, walls, roof) is ray-cast per
pixel and textured from an atlas; boxes, beams and prisms are convex polygons clipped at the
near plane and filled far-to-near; plant leaves are projected 3D ellipses (a far plant is one
ellipse). Depth comes from the same painter pass (a primitive-id buffer plus each primitive's
plane equation).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from greenloop.datasets.synthetic.camera import camera_intrinsics, DEFAULT_SIZE
from greenloop.datasets.synthetic.scene import FOG_COLOR, Scene
from greenloop.datasets.synthetic.textures import TEX_RES

NEAR = 0.1                # near clipping plane (metres)
FAR = 30.0                # primitives farther than this are culled (metres)
FOG_DIST = 28.0           # metres: haze, contrast halves every ~19 m
SHIFT = 4                 # sub-pixel bits for OpenCV drawing
ONE = 1 << SHIFT


def _clip_near(poly: np.ndarray, near: float = NEAR) -> np.ndarray:
    """Sutherland-Hodgman clip of a camera-frame polygon (k, 3) against z >= near."""
    out = []
    k = len(poly)
    for i in range(k):
        a, b = poly[i], poly[(i + 1) % k]
        ina, inb = a[2] >= near, b[2] >= near
        if ina:
            out.append(a)
        if ina != inb:
            t = (near - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.array(out) if len(out) >= 3 else np.zeros((0, 3))


@dataclass
class _Grid:
    """Per-size precomputations: normalised ray grid and post-processing helpers."""
    fx: float
    fy: float
    cx: float
    cy: float
    w: int
    h: int
    xg: np.ndarray        # (H, W) float32 (u - cx) / fx
    yg: np.ndarray        # (H, W) float32 (v - cy) / fy


def _grid(size) -> _Grid:
    """``_Grid`` for ``size`` = (width, height) pixels: the scaled D435i intrinsics and the ray grid."""
    k = camera_intrinsics(size)
    w, h = k["width"], k["height"]
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    xg = (u - k["cx"]) / k["fx"]
    yg = (v - k["cy"]) / k["fy"]
    return _Grid(k["fx"], k["fy"], k["cx"], k["cy"], w, h, xg, yg)


def _render_hall(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray):
    """Ray-cast the hall box (floor, roof, four walls) with distance fog.

    R (3, 3), o (3,): camera-to-hall rotation and camera centre. Returns (bgr (H, W, 3) uint8,
    depth (H, W) float32 metres along the optical axis).
    """
    r = R.astype(np.float32)
    xg, yg = g.xg, g.yg
    HALL_WIDTH, HALL_HEIGHT, HALL_DEPTH = scene.hall_size   # noqa: N806 (the hall's constants)
    ox, oy, oz = (float(v) for v in o)
    d = [r[i, 0] * xg + r[i, 1] * yg + r[i, 2] for i in range(3)]   # hall-frame ray, camera z = 1
    # inverse ray parameter to the wall each ray reaches: the larger, the nearer
    inv = [np.maximum(d[0] * (1.0 / (HALL_WIDTH - ox)), d[0] * (-1.0 / ox)),
           np.maximum(d[1] * (1.0 / (HALL_HEIGHT - oy)), d[1] * (-1.0 / oy)),
           np.maximum(d[2] * (1.0 / (HALL_DEPTH - oz)), d[2] * (-1.0 / oz))]
    best = np.maximum(np.maximum(inv[0], inv[1]), inv[2])
    t = 1.0 / best
    is_y = inv[1] >= best
    is_x = ~is_y & (inv[0] >= best)
    rows = scene.atlas_rows
    off = np.where(is_y, np.where(d[1] < 0, rows[0], rows[1]),
                   np.where(is_x, np.where(d[0] < 0, rows[2], rows[3]),
                            np.where(d[2] < 0, rows[4], rows[5])))
    s = 1.0 / TEX_RES
    px = (ox + t * d[0]) * s
    pz = (oz + t * d[2]) * s
    mu = np.where(is_x, pz, px)
    mv = np.where(is_y, pz, (HALL_HEIGHT - oy) * s - t * d[1] * s) + off
    img = cv2.remap(scene.atlas, mu.astype(np.float32), mv.astype(np.float32), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    keep = cv2.exp(t * np.float32(-1.0 / FOG_DIST))
    fog = np.float32(1.0) - keep
    img = (img * keep[..., None] + fog[..., None] * scene.fog_color).astype(np.uint8)
    return img, t.astype(np.float32)


def _draw_list(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray):
    """Visible primitives, clipped, projected and sorted far-to-near.

    R (3, 3), o (3,): camera-to-hall rotation and camera centre (metres).
    Returns (items, planes) with items a list of draw commands and planes (K + 1, 3) float64
    inverse-depth coefficients (A, B, C): 1/z = A*(u-cx)/fx + B*(v-cy)/fy + C for primitive id
    1..K (row 0 unused: the hall).
    """
    pkeys, pplanes, polys, pcol = _draw_polygons(scene, g, R, o)
    C, rpx, detail, blob = _plant_visibility(scene, g, R, o)
    leaves = _leaf_ellipses(scene, g, R, o, detail)
    blobs = _blob_ellipses(scene, g, C, rpx, blob)
    return _sorted_items(pkeys, pplanes, polys, pcol, leaves, blobs, scene.fog_color)


def _draw_polygons(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray):
    """The scene's polygons that face the camera and reach into the view, near-clipped and
    projected.

    R (3, 3), o (3,): camera-to-hall rotation and camera centre (metres).
    Returns (keys (K,) float64 painter's distance in metres (their object's nearest or farthest
    point, see ``Scene.obj_far``), planes (K, 3) float64 inverse-depth coefficients (see
    ``_draw_list``), polys (list of K (k, 2) int32 image corners in 1/ONE pixels, or None where
    clipping left nothing), colours (list of K BGR triples, fogged)).
    """
    fx, fy, cx, cy, w, h = g.fx, g.fy, g.cx, g.cy, g.w, g.h
    V = (scene.quads - o) @ R                      # (Q, 4, 3) camera frame
    x, y, z = V[..., 0], V[..., 1], V[..., 2]
    m = 4.0
    facing = np.einsum("ij,ij->i", scene.quad_normal, o - scene.quads[:, 0]) > 1e-9
    vis = (facing & (z.max(1) > NEAR) & (z.min(1) < FAR)
           & ~np.all(fx * x - (w - cx + m) * z > 0, 1) & ~np.all(fx * x + (cx + m) * z < 0, 1)
           & ~np.all(fy * y - (h - cy + m) * z > 0, 1) & ~np.all(fy * y + (cy + m) * z < 0, 1))
    qi = np.nonzero(vis)[0]
    lo, hi = scene.obj_lo, scene.obj_hi
    near_d = np.linalg.norm(np.clip(o, lo, hi) - o, axis=1)
    far_d = np.linalg.norm(np.maximum(np.abs(o - lo), np.abs(o - hi)), axis=1)
    okey = np.where(scene.obj_far, far_d, near_d)
    pkeys = okey[scene.quad_obj[qi]]
    nc = scene.quad_normal[qi] @ R
    dpl = np.einsum("ij,ij->i", nc, V[qi, 0])
    pplanes = nc / dpl[:, None]
    Vq = V[qi]
    zq = Vq[..., 2]
    clipped = zq.min(1) < NEAR
    with np.errstate(divide="ignore", invalid="ignore"):
        U = np.stack([fx * Vq[..., 0] / zq + cx, fy * Vq[..., 1] / zq + cy], -1)
    P = np.clip(np.rint(U * ONE), -2**24, 2**24).astype(np.int32)
    polys = []
    for j in range(len(qi)):
        if clipped[j]:
            c = _clip_near(Vq[j])
            if len(c) == 0:
                polys.append(None)
                continue
            uv = np.stack([fx * c[:, 0] / c[:, 2] + cx, fy * c[:, 1] / c[:, 2] + cy], -1)
            polys.append(np.clip(np.rint(uv * ONE), -2**24, 2**24).astype(np.int32))
        else:
            polys.append(P[j])
    pcol = _fog(scene.quad_color[qi], pkeys, scene.fog_color).tolist()
    return pkeys, pplanes, polys, pcol


def _plant_visibility(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray):
    """Which plants are drawn, and how: leaf by leaf when near, as one blob when far.

    R (3, 3), o (3,): camera-to-hall rotation and camera centre (metres).
    Returns (C (P, 3) plant centres in the camera frame (metres), rpx (P,) plant radius in
    pixels, detail (P,) bool drawn leaf by leaf (radius >= 6 px), blob (P,) bool drawn as one
    ellipse (visible but smaller); holes vanish below 0.6 px).
    """
    fx, fy, cx, cy, w, h = g.fx, g.fy, g.cx, g.cy, g.w, g.h
    m = 4.0
    C = (scene.plant_center - o) @ R
    pz = C[:, 2]
    rpx = fx * scene.plant_radius / np.maximum(pz, 1e-3)
    rr = scene.plant_radius * 1.5
    pvis = ((pz > 0.15) & (pz < FAR)
            & (fx * C[:, 0] - (w - cx + m) * pz < fx * rr) & (fx * C[:, 0] + (cx + m) * pz > -fx * rr)
            & (fy * C[:, 1] - (h - cy + m) * pz < fy * rr) & (fy * C[:, 1] + (cy + m) * pz > -fy * rr)
            & ((rpx > 0.6) | (scene.plant_flat == 0)))     # holes vanish below a pixel
    detail = pvis & (rpx >= 6.0)
    blob = pvis & ~detail
    return C, rpx, detail, blob


def _leaf_ellipses(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray, detail: np.ndarray):
    """Image ellipses of the leaves of the plants marked in ``detail`` (P,) bool, leaves nearer
    than 0.12 m dropped.

    Returns (centre (L, 2) pixels, axes (L, 2) semi-axes in pixels, angle (L,) degrees,
    colour (L, 3) BGR before fog, key (L,) distance to the camera in metres, depth (L,) metres
    along the optical axis).
    """
    fx, fy, cx, cy = g.fx, g.fy, g.cx, g.cy
    counts = np.diff(scene.plant_leaves)
    pid = np.nonzero(detail)[0]
    if len(pid):
        cnt = counts[pid]
        lidx = np.repeat(scene.plant_leaves[pid] - (np.cumsum(cnt) - cnt), cnt) + np.arange(cnt.sum())
    else:
        lidx = np.zeros(0, np.int64)
    Lc = (scene.leaf_center[lidx] - o) @ R
    lz = Lc[:, 2]
    keep = lz > 0.12
    lidx, Lc, lz = lidx[keep], Lc[keep], lz[keep]
    A1 = scene.leaf_a1[lidx] @ R
    A2 = scene.leaf_a2[lidx] @ R
    e_c = np.stack([fx * Lc[:, 0] / lz + cx, fy * Lc[:, 1] / lz + cy], 1)
    e_ax, e_ang = _project_ellipses(Lc, A1, A2, fx, fy)
    return e_c, e_ax, e_ang, scene.leaf_color[lidx], np.linalg.norm(Lc, axis=1), lz


def _blob_ellipses(scene: Scene, g: _Grid, C: np.ndarray, rpx: np.ndarray, blob: np.ndarray):
    """One image ellipse per far plant marked in ``blob`` (P,) bool, squashed by the viewing
    elevation; C (P, 3) camera-frame centres (metres), rpx (P,) radii in pixels.

    Returns the same six arrays as ``_leaf_ellipses`` (angle 0, the plant's mean colour).
    """
    fx, fy, cx, cy = g.fx, g.fy, g.cx, g.cy
    bid = np.nonzero(blob)[0]
    Cb = C[bid]
    bz = Cb[:, 2]
    elev = np.abs(Cb[:, 1]) / np.linalg.norm(Cb, axis=1)
    squash = np.where(scene.plant_flat[bid] == 1, np.clip(elev, 0.05, 1), np.clip(elev + 0.55, 0, 1))
    b_r = rpx[bid] * 0.95
    b_ax = np.stack([b_r, b_r * squash], 1)
    b_c = np.stack([fx * Cb[:, 0] / bz + cx, fy * Cb[:, 1] / bz + cy], 1)
    b_key = np.linalg.norm(Cb, axis=1)
    return b_c, b_ax, np.zeros(len(bid)), scene.plant_color[bid], b_key, bz


def _sorted_items(pkeys, pplanes, polys, pcol, leaves, blobs, fog_color=FOG_COLOR):
    """Merge polygons (from ``_draw_polygons``) and ellipses (``leaves`` then ``blobs``, each the
    six arrays of ``_leaf_ellipses``, fogged towards ``fog_color`` (3,) BGR) into one far-to-near
    draw list.

    Returns (items, planes) as ``_draw_list``: items are (0, polygon, colour, id) or
    (1, (centre, axes, angle) in 1/ONE pixels and degrees, colour, id), ids 1..K in input order
    (polygons first); planes (K + 1, 3) with 1/z = C (A = B = 0) for the ellipses.
    """
    ec, eax, eang, ecol, ekey, edepth = (np.concatenate([a, b]) for a, b in zip(leaves, blobs))
    ecol = _fog(ecol, ekey, fog_color).tolist()
    eci = np.rint(ec * ONE).astype(np.int64).tolist()
    eai = np.maximum(np.rint(eax * ONE), 1).astype(np.int64).tolist()
    eang = eang.tolist()

    npoly = len(polys)
    keys = np.concatenate([pkeys, ekey])
    order = np.argsort(-keys, kind="stable")
    planes = np.zeros((1 + len(keys), 3))
    planes[1:npoly + 1] = pplanes
    planes[npoly + 1:, 2] = 1.0 / edepth
    items = []
    for k in order.tolist():
        if k < npoly:
            if polys[k] is not None:
                items.append((0, polys[k], pcol[k], k + 1))
        else:
            e = k - npoly
            items.append((1, (eci[e], eai[e], eang[e]), ecol[e], k + 1))
    return items, planes


def _fog(color: np.ndarray, dist: np.ndarray, fog_color=FOG_COLOR) -> np.ndarray:
    """Colours (K, 3) seen through ``dist`` (K,) metres of haze (one value per primitive) of
    colour ``fog_color`` (3,) BGR."""
    keep = np.exp(-np.asarray(dist, np.float64) / FOG_DIST)[:, None]
    return color * keep + fog_color * (1.0 - keep)


def _project_ellipses(Cc, A1, A2, fx, fy):
    """Image ellipses of small 3D ellipses (centre Cc, semi-axis vectors A1, A2; camera frame).

    All (L, 3). Uses the projection's Jacobian at the centre. Returns (axes (L, 2) semi-axes in
    pixels, angle (L,) degrees for cv2.ellipse).
    """
    x, y, z = Cc[:, 0], Cc[:, 1], Cc[:, 2]

    def jac(a):
        return np.stack([fx * (a[:, 0] - x * a[:, 2] / z) / z, fy * (a[:, 1] - y * a[:, 2] / z) / z], 1)

    u, v = jac(A1), jac(A2)
    a = u[:, 0] ** 2 + v[:, 0] ** 2
    b = u[:, 0] * u[:, 1] + v[:, 0] * v[:, 1]
    c = u[:, 1] ** 2 + v[:, 1] ** 2
    root = np.sqrt(((a - c) / 2) ** 2 + b ** 2)
    l1 = np.sqrt(np.maximum((a + c) / 2 + root, 0))
    l2 = np.sqrt(np.maximum((a + c) / 2 - root, 0))
    ang = np.degrees(0.5 * np.arctan2(2 * b, a - c))
    return np.stack([l1, l2], 1), ang


def render_frame(scene: Scene, pose: np.ndarray, size=DEFAULT_SIZE, grid: _Grid | None = None):
    """Render one clean frame (no sensor effects).

    scene: from ``build_scene``; pose: (4, 4) camera-to-hall (from ``route_world``);
    size: (width, height) pixels. Returns (bgr (H, W, 3) uint8, depth (H, W) float32 metres
    along the optical axis, every pixel valid).
    """
    g = grid if grid is not None else _grid(size)
    R = np.asarray(pose[:3, :3], np.float64)
    o = np.asarray(pose[:3, 3], np.float64)
    img, hall_depth = _render_hall(scene, g, R, o)
    items, planes = _draw_list(scene, g, R, o)
    ids = np.zeros((g.h, g.w), np.int32)
    fill, ell = cv2.fillConvexPoly, cv2.ellipse
    aa, l8 = cv2.LINE_AA, cv2.LINE_8
    for kind, geom, col, pid in items:
        if kind == 0:
            fill(img, geom, col, aa, SHIFT)
            fill(ids, geom, pid, l8, SHIFT)
        else:
            c, ax, ang = geom
            ell(img, c, ax, ang, 0, 360, col, -1, l8, SHIFT)
            ell(ids, c, ax, ang, 0, 360, pid, -1, l8, SHIFT)
    depth = hall_depth
    hit = ids > 0
    if hit.any():
        pl = planes[ids[hit]]
        inv = pl[:, 0] * g.xg[hit] + pl[:, 1] * g.yg[hit] + pl[:, 2]
        depth = depth.copy()
        depth[hit] = np.where(inv > 1e-6, 1.0 / np.maximum(inv, 1e-6), hall_depth[hit])
    return img, depth
