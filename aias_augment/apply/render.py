"""Offscreen rendering: the only module that imports pyrender.

Rendering runs headless through EGL (Mesa llvmpipe on CPU). The OpenGL context is created lazily, once per process,
on first use. A process must not fork after creating it (the children hang): use ``spawn``/``forkserver`` for
worker pools that render after the parent rendered; :func:`_renderer` refuses, with a clear error, to reuse a
context inherited through fork.

Outputs are in the OpenCV camera convention of :mod:`aias_augment.core.geometry` with pixel centres at integer
coordinates: pyrender's window convention puts pixel centres at +0.5, which :func:`_pyrender_camera` compensates.

pyrender (and trimesh) are imported by the functions that render, on first use: their import (~0.4 s with freetype,
pyglet and networkx) is not paid by a process that never renders, such as a DataLoader worker that pastes
insertion variants or finds its views cached (a non-persistent worker pays its imports every epoch).
"""

from __future__ import annotations

import atexit
import logging
import math
import os
import sys
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np  # noqa: E402

if TYPE_CHECKING:  # imported by the functions that render (see above)
    import pyrender

from aias_augment.assets.asset import Asset  # noqa: E402
from aias_augment.core.geometry import Intrinsics, check_rigid, invert_rigid, norm3, opengl_from_opencv  # noqa: E402
from aias_augment.core.srgb import linear_to_srgb, srgb_to_linear  # noqa: E402

__all__ = [
    "RenderLayers",
    "ShadowLayers",
    "render_object",
    "render_object_window",
    "render_ground_shadow",
    "supersampled_layers",
    "window_roi",
    "crop_intrinsics",
    "srgb_to_linear",
    "linear_to_srgb",
]

log = logging.getLogger(__name__)
_STATE: dict = {"renderer": None, "pid": None, "size": None}


def _release() -> None:
    """Delete the context before interpreter teardown (avoids PyOpenGL errors from __del__ at exit)."""
    r = _STATE.get("renderer")
    if r is not None and _STATE.get("pid") == os.getpid():
        try:
            r.delete()
        except Exception:  # best effort at exit
            pass
    _STATE["renderer"] = None


atexit.register(_release)


def _block_triton_under_llvmpipe() -> None:
    """Mesa's llvmpipe has loaded its LLVM into this process; Triton's ``libtriton`` loads another one, and importing
    it now crashes the interpreter (a segfault: torch imports it lazily, e.g. from ``torch.optim.Adam`` through
    ``torch._dynamo``, in a process that rendered first). Triton compiles GPU kernels only, and a process rendering
    on llvmpipe has no GPU context: when it is not imported yet, ``import triton`` is made to raise ImportError
    (torch then runs without it), and this is logged. A process that imported Triton before rendering keeps it
    (that order does not crash)."""
    if "triton" in sys.modules:
        return
    try:
        from OpenGL import GL

        name = GL.glGetString(GL.GL_RENDERER) or b""
    except Exception:  # no current context to ask: leave the imports as they are
        return
    if b"llvmpipe" in name:
        sys.modules["triton"] = None
        log.debug(
            "render: %s holds its own LLVM; 'import triton' now raises ImportError in this process (loading "
            "libtriton's LLVM beside it crashes the interpreter)",
            name.decode(errors="replace"),
        )


def _renderer(width: int, height: int) -> "pyrender.OffscreenRenderer":
    import pyrender

    pid = os.getpid()
    if _STATE["renderer"] is not None and _STATE["pid"] != pid:
        raise RuntimeError(
            "aias_augment.apply.render: this process was forked after its parent created an EGL renderer; rendering here "
            "would hang. Use a 'spawn' or 'forkserver' multiprocessing context (e.g. DataLoader("
            "multiprocessing_context='spawn')) or do not render in the parent before forking."
        )
    if _STATE["renderer"] is None:
        _STATE["renderer"] = pyrender.OffscreenRenderer(width, height)
        _STATE["pid"] = pid
        _block_triton_under_llvmpipe()
    r = _STATE["renderer"]
    if (r.viewport_width, r.viewport_height) != (width, height):
        r.viewport_width, r.viewport_height = width, height
    return r


def _pyrender_camera(intr: Intrinsics, ssaa: int, znear: float, zfar: float) -> "pyrender.IntrinsicsCamera":
    # OpenCV pixel centres are integers; OpenGL window pixel centres are at +0.5. With supersampling factor s, the
    # OpenCV coordinate u maps to s*(u + 0.5) in the big window.
    import pyrender

    s = float(ssaa)
    return pyrender.IntrinsicsCamera(
        fx=intr.fx * s, fy=intr.fy * s, cx=(intr.cx + 0.5) * s, cy=(intr.cy + 0.5) * s, znear=znear, zfar=zfar
    )


def _camera_pose_gl(cam_from_world: np.ndarray) -> np.ndarray:
    """pyrender wants world_from_glcam."""
    return invert_rigid(opengl_from_opencv(cam_from_world))


def _downsample(x: np.ndarray, s: int) -> np.ndarray:
    """The mean of each ``s`` x ``s`` block of ``x`` (H, W[, C]): ``x.reshape(h, s, w, s, ...).mean(axis=(1, 3))``.
    For ``s`` 2 on a contiguous float array the four quarter-grids are summed in the order numpy's reduction adds
    them (pairwise for one channel, in turn for several), the same numbers at a fraction of the cost (tested
    against the reduction)."""
    if s == 1:
        return x
    h, w = x.shape[0] // s, x.shape[1] // s
    if s == 2 and w > 1 and x.ndim in (2, 3) and x.flags.c_contiguous and x.dtype in (np.float32, np.float64):
        a, b, c, d = x[0::2, 0::2], x[0::2, 1::2], x[1::2, 0::2], x[1::2, 1::2]
        total = (a + b) + (c + d) if x.ndim == 2 or x.shape[2] == 1 else ((a + b) + c) + d
        return total / 4
    return x.reshape(h, s, w, s, *x.shape[2:]).mean(axis=(1, 3))


@dataclass(frozen=True, eq=False)
class RenderLayers:
    """Per-object render in one camera.

    albedo_linear: (H, W, 3) float32 linear base colour (texture decoded from sRGB), premultiplied by nothing.
    alpha: (H, W) float32 pixel coverage in [0, 1] (fractional at edges when supersampled).
    depth: (H, W) float32 z-depth in metres of the object surface, 0 where the object does not cover the pixel.
    normals_in_cam: (H, W, 3) float32 unit surface normals in the OpenCV camera frame (0 outside the object).
    """

    albedo_linear: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    normals_in_cam: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        return self.alpha > 0.5


#: GPU-side meshes per unscaled asset (weak keys: an asset that is gone frees its entry). One pyrender Mesh per asset
#: holding all its parts as primitives, so the parts are drawn in list order: pyrender draws the *nodes* of a scene
#: in the iteration order of a set hashed by object address, which made coplanar geometry (the ground patch under an
#: object) resolve differently from one process history to the next.
_MESH_CACHE: "weakref.WeakKeyDictionary[Asset, dict]" = weakref.WeakKeyDictionary()


def _to_pyrender_mesh(asset: Asset, normals: bool) -> tuple["pyrender.Mesh", np.ndarray]:
    """(mesh of the asset's unscaled root, 4x4 node pose that scales it to ``asset``). Built once per root asset
    and process (a forked child rebuilds: GL objects do not survive a fork)."""
    import pyrender
    import trimesh

    root = asset.render_root if asset.render_root is not None else asset
    entry = _MESH_CACHE.get(root)
    if entry is None or entry["pid"] != os.getpid():
        entry = {"pid": os.getpid()}
        _MESH_CACHE[root] = entry
    key = "normals" if normals else "albedo"
    if key not in entry:
        prims = []
        for m in root.meshes:
            if normals:
                n = np.asarray(m.vertex_normals, dtype=np.float64)
                colors = np.clip((n + 1.0) * 0.5 * 255.0 + 0.5, 0, 255).astype(np.uint8)
                plain = trimesh.Trimesh(
                    m.vertices, m.faces, process=False, vertex_colors=np.c_[colors, np.full(len(colors), 255, np.uint8)]
                )
                prims += pyrender.Mesh.from_trimesh(plain, smooth=True).primitives
            else:
                # Per-face colours need flat (unsmoothed) vertices in pyrender; textures and vertex colours are smooth.
                smooth = getattr(m.visual, "kind", None) != "face"
                prims += pyrender.Mesh.from_trimesh(m, smooth=smooth).primitives
        entry[key] = pyrender.Mesh(primitives=prims)
    pose = np.diag([asset.render_scale] * 3 + [1.0])
    return entry[key], pose


def _resident_meshes(asset: Asset, with_normals: bool) -> tuple:
    """The asset's albedo (and normals) meshes, built if needed: kept on the GPU across its two flat passes."""
    meshes = [_to_pyrender_mesh(asset, False)[0]]
    if with_normals:
        meshes.append(_to_pyrender_mesh(asset, True)[0])
    return tuple(meshes)


def _render_flat(
    mesh: "pyrender.Mesh",
    mesh_pose: np.ndarray,
    cam_from_object: np.ndarray,
    intr: Intrinsics,
    ssaa: int,
    znear: float,
    zfar: float,
    resident: tuple = (),
) -> tuple[np.ndarray, np.ndarray]:
    """Unlit render of ``mesh``. ``resident``: other meshes put in the scene but not drawn, so that pyrender keeps
    their buffers and textures on the GPU (it deletes whatever the scene being rendered lacks, and uploads it again
    next time: the texture upload was the largest part of a small render). A flat render with explicit near/far
    planes does not depend on undrawn nodes: same bytes."""
    import pyrender

    scene = pyrender.Scene(bg_color=np.zeros(4), ambient_light=np.ones(3))
    scene.add(mesh, pose=mesh_pose)
    hidden = [m for m in resident if m is not mesh]
    for m in hidden:
        scene.add(m, pose=mesh_pose)
    # Object frame is the scene's world frame.
    scene.add(_pyrender_camera(intr, ssaa, znear, zfar), pose=_camera_pose_gl(cam_from_object))
    r = _renderer(intr.width * ssaa, intr.height * ssaa)
    for m in hidden:
        m.is_visible = False
    try:
        color, depth = r.render(scene, flags=pyrender.RenderFlags.FLAT | pyrender.RenderFlags.RGBA)
    finally:  # outside this call every cached mesh is visible (the shadow catcher draws the albedo mesh)
        for m in hidden:
            m.is_visible = True
    return color, depth


def window_roi(
    points_in_obj: np.ndarray, cam_from_object: np.ndarray, intr: Intrinsics, margin_px: float, znear: float
) -> tuple[int, int, int, int]:
    """Pixel window (x0, y0, x1, y1), x1/y1 exclusive, that contains the projection of ``points_in_obj`` (whose
    convex hull bounds what is rendered) plus a margin; the full frame when a point is not in front of the camera."""
    p = np.asarray(points_in_obj, np.float64).reshape(-1, 3) @ cam_from_object[:3, :3].T + cam_from_object[:3, 3]
    z = p[:, 2]
    if (z <= znear).any() or not np.isfinite(p).all():
        return 0, 0, intr.width, intr.height
    K = intr.K  # project_points' arithmetic, in the same order
    u = K[0, 0] * p[:, 0] / z + K[0, 1] * p[:, 1] / z + K[0, 2]
    v = K[1, 1] * p[:, 1] / z + K[1, 2]
    W, H = intr.width, intr.height
    x0 = min(max(math.floor(float(u.min()) - margin_px), 0), W)
    y0 = min(max(math.floor(float(v.min()) - margin_px), 0), H)
    x1 = min(max(math.ceil(float(u.max()) + margin_px) + 1, 0), W)
    y1 = min(max(math.ceil(float(v.max()) + margin_px) + 1, 0), H)
    return x0, y0, x1, y1


def crop_intrinsics(intr: Intrinsics, roi: tuple[int, int, int, int]) -> Intrinsics:
    x0, y0, x1, y1 = roi
    return Intrinsics(intr.fx, intr.fy, intr.cx - x0, intr.cy - y0, x1 - x0, y1 - y0)


def _translation(t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = t
    return T


def _paste(full_shape: tuple, roi: tuple[int, int, int, int], crop: np.ndarray, fill: float = 0.0) -> np.ndarray:
    out = np.full(full_shape + crop.shape[2:], fill, dtype=np.float32)
    x0, y0, x1, y1 = roi
    out[y0:y1, x0:x1] = crop
    return out


def render_object(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    *,
    ssaa: int = 1,
    znear: float = 0.05,
    zfar: float = 2000.0,
    with_normals: bool = True,
) -> RenderLayers:
    """Render ``asset`` (canonical object frame) seen by an OpenCV camera at ``cam_from_object``.

    ``ssaa``: supersampling factor (1 = aliased binary coverage, 2-4 = anti-aliased edges; cost grows as ssaa^2).
    Full-frame layers; :func:`render_object_window` returns only the window around the object.
    """
    full = (intrinsics.height, intrinsics.width)
    roi, layers = render_object_window(
        asset, cam_from_object, intrinsics, ssaa=ssaa, znear=znear, zfar=zfar, with_normals=with_normals
    )
    return RenderLayers(
        _paste(full, roi, layers.albedo_linear),
        _paste(full, roi, layers.alpha),
        _paste(full, roi, layers.depth),
        _paste(full, roi, layers.normals_in_cam),
    )


def render_object_window(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    *,
    ssaa: int = 1,
    znear: float = 0.05,
    zfar: float = 2000.0,
    with_normals: bool = True,
) -> tuple[tuple[int, int, int, int], RenderLayers]:
    """(roi, layers): :func:`render_object` inside the window roi = (x0, y0, x1, y1) (x1/y1 exclusive) that holds
    the projected bounding box of the object; layers are (y1 - y0, x1 - x0[, 3]) (empty when the object is off
    screen)."""
    cam_from_object = check_rigid(cam_from_object, "cam_from_object")
    if ssaa < 1 or int(ssaa) != ssaa:
        raise ValueError(f"ssaa must be a positive integer, got {ssaa}")
    # Only the window around the object is rendered (the projected bounding-box corners bound the silhouette).
    roi = window_roi(asset.corners_m(), cam_from_object, intrinsics, 2.0, znear)
    if roi[2] <= roi[0] or roi[3] <= roi[1]:
        roi = (0, 0, 0, 0)
        z = np.zeros((0, 0), np.float32)
        return roi, RenderLayers(np.zeros((0, 0, 3), np.float32), z, z.copy(), np.zeros((0, 0, 3), np.float32))
    return roi, _render_object_window(
        asset, cam_from_object, crop_intrinsics(intrinsics, roi), ssaa, znear, zfar, with_normals
    )


def _render_object_window(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    ssaa: int,
    znear: float,
    zfar: float,
    with_normals: bool,
) -> RenderLayers:
    resident = _resident_meshes(asset, with_normals)
    color, depth = _render_flat(
        *_to_pyrender_mesh(asset, False), cam_from_object, intrinsics, ssaa, znear, zfar, resident
    )
    covered = (depth > 0).astype(np.float32)
    albedo = srgb_to_linear(color[..., :3].astype(np.float32) / 255.0) * covered[..., None]
    if with_normals:
        ncol, _ = _render_flat(
            *_to_pyrender_mesh(asset, True), cam_from_object, intrinsics, ssaa, znear, zfar, resident
        )
        n_obj = ncol[..., :3].astype(np.float32) / 255.0 * 2.0 - 1.0
        n_cam = n_obj @ cam_from_object[:3, :3].T.astype(np.float32)
    else:
        n_cam = np.zeros(color.shape[:2] + (3,), np.float32)
    return supersampled_layers(covered, albedo, n_cam, depth.astype(np.float32), ssaa)


def supersampled_layers(
    covered: np.ndarray, albedo: np.ndarray, n_cam: np.ndarray, depth: np.ndarray, ssaa: int
) -> RenderLayers:
    """Pixel layers from ``ssaa`` x ``ssaa`` sub-samples per pixel: ``covered`` (h, w) float 0/1, ``albedo`` (h, w, 3)
    linear and 0 where not covered, ``n_cam`` (h, w, 3) camera-frame normals, ``depth`` (h, w) z-depth, 0 where not
    covered. Coverage is the covered share; colour, normal and depth are the means over the covered sub-samples."""
    alpha = _downsample(covered, ssaa)
    # Average colour over covered sub-samples only (un-premultiply), z-depth: nearest covered sub-sample mean.
    w = np.maximum(alpha, 1e-6)[..., None]  # eps: avoid 0/0 where nothing is covered (result forced to 0 below)
    albedo = _downsample(albedo, ssaa) / w
    n_cam = _downsample(n_cam * covered[..., None], ssaa)
    n_len = norm3(n_cam, keepdims=True)
    n_cam = np.where(n_len > 1e-6, n_cam / np.maximum(n_len, 1e-6), 0.0)
    depth_sum = _downsample(depth, ssaa)
    d = np.where(alpha > 0, depth_sum / np.maximum(alpha, 1e-6), 0.0)
    inside = alpha > 0
    albedo[~inside] = 0
    return RenderLayers(
        albedo.astype(np.float32), alpha.astype(np.float32), d.astype(np.float32), n_cam.astype(np.float32)
    )


@dataclass(frozen=True, eq=False)
class ShadowLayers:
    """Shadow catcher on the ground plane (z = 0 of the object frame).

    visibility: (H, W) float32 fraction of the sun visible from the ground point seen at each pixel (1 = lit), 1 where
        no ground patch was rendered.
    ground_mask: (H, W) bool, pixels where the ground patch was rendered.
    ground_depth: (H, W) float32 z-depth of the ground patch (0 outside).
    Only the window holding the object, its shadow and a ring of ground around its footprint is rendered.
    """

    visibility: np.ndarray
    ground_mask: np.ndarray
    ground_depth: np.ndarray
    roi: tuple[int, int, int, int] = (0, 0, 0, 0)  # window (x0, y0, x1, y1) that was rendered; 1/False/0 outside


def _ground_patch(radius: float, node_origin: np.ndarray) -> "pyrender.Mesh":
    """The square z = 0, |x|, |y| <= radius, with vertices relative to ``node_origin`` (the node's translation)."""
    import pyrender
    import trimesh

    quad = trimesh.Trimesh(
        vertices=np.array(
            [[-radius, -radius, 0], [radius, -radius, 0], [radius, radius, 0], [-radius, radius, 0]], dtype=np.float64
        )
        - node_origin,
        faces=np.array([[0, 1, 2], [0, 2, 3]]),
        process=False,
    )
    mat = pyrender.MetallicRoughnessMaterial(
        baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0, roughnessFactor=1.0
    )
    return pyrender.Mesh.from_trimesh(quad, material=mat, smooth=False)


def unit_sun(sun_direction: np.ndarray) -> np.ndarray:
    sun = np.asarray(sun_direction, dtype=np.float64).reshape(3)
    if not np.isfinite(sun).all():
        raise ValueError("sun direction: contains NaN or Inf")
    norm = math.sqrt(float(sun @ sun))
    if norm < 1e-9:
        raise ValueError("sun direction has zero length")
    return sun / norm


def shadow_window(
    asset: Asset, cam_from_object: np.ndarray, intrinsics: Intrinsics, sun: np.ndarray, znear: float = 0.05
) -> tuple[tuple[int, int, int, int], float]:
    """(roi, ground patch radius in m) of the shadow catcher: the window holding the object, its whole shadow (each
    bounding-box corner projected along the unit ``sun`` onto z = 0) and a ring of ground around its footprint."""
    corners = asset.corners_m()
    got = asset.__dict__.get("_shadow_ring")  # a memo on the (immutable) asset, as its bounds
    if got is None:
        ext = asset.extents_m
        ring = max(float(ext[2]), float(ext[:2].max()))  # ground around the footprint kept for contact shadows
        lo, hi = asset.bounds_m
        got = asset.__dict__["_shadow_ring"] = (
            ring,
            np.array(
                [
                    [lo[0] - ring, lo[1] - ring, 0],
                    [hi[0] + ring, lo[1] - ring, 0],
                    [lo[0] - ring, hi[1] + ring, 0],
                    [hi[0] + ring, hi[1] + ring, 0],
                ]
            ),
        )
    ring, ring_pts = got
    pts = [corners, ring_pts]
    if sun[2] > 0.02:
        # The whole shadow: each corner projected along the sun onto z = 0 (length height / tan(elevation)), with the
        # ray length capped at 60 m for a sun grazing the horizon.
        t = np.minimum(corners[:, 2:3] / sun[2], 60.0)
        reach = float(t.max())
        pts.append(corners - t * sun)
        radius = float(max(np.abs(corners[:, :2]).max() + reach, ring) * 1.2)
    else:
        radius = float(np.abs(corners[:, :2]).max() + ring)
    return window_roi(np.concatenate(pts), cam_from_object, intrinsics, 2.0, znear), radius


def render_ground_shadow(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    sun_direction_in_object: np.ndarray,
    *,
    patch_radius_m: float | None = None,
    znear: float = 0.05,
    zfar: float = 2000.0,
    window: bool = False,
) -> ShadowLayers:
    """Differential shadow catcher: a Lambertian ground patch lit by the sun alone, rendered with and without the
    object; the ratio of the two (in linear radiance) is the sun visibility. ``sun_direction_in_object`` points from
    the scene toward the sun; a sun at or below the horizon (z <= 0.02) casts no shadow (visibility 1).
    ``window``: the layers cover only the rendered window ``roi`` (not the full frame).
    """
    import pyrender

    cam_from_object = check_rigid(cam_from_object, "cam_from_object")
    sun = unit_sun(sun_direction_in_object)
    full = (intrinsics.height, intrinsics.width)
    roi, radius_default = shadow_window(asset, cam_from_object, intrinsics, sun, znear)
    if patch_radius_m is None:
        patch_radius_m = radius_default
    if roi[2] <= roi[0] or roi[3] <= roi[1]:
        if window:
            roi, full = (0, 0, 0, 0), (0, 0)
        return ShadowLayers(np.ones(full, np.float32), np.zeros(full, bool), np.zeros(full, np.float32), roi)
    if window:
        full = None
    crop = crop_intrinsics(intrinsics, roi)
    h, w = crop.height, crop.width
    base = pyrender.Scene(bg_color=np.zeros(4), ambient_light=np.zeros(3))
    # pyrender sorts opaque nodes by the distance of their origin to the camera (far first) and breaks ties by set
    # order, i.e. by memory address. The ground node's origin is put beyond the object's origin (the object frame's
    # origin, on the far side from the camera), so the ground is always drawn first: same bytes in every process.
    cam_in_obj = invert_rigid(cam_from_object)[:3, 3]
    away = -cam_in_obj / max(float(np.linalg.norm(cam_in_obj)), 1e-9)
    ground_origin = away * max(patch_radius_m, 1.0)
    base.add(_ground_patch(patch_radius_m, ground_origin), pose=_translation(ground_origin))
    base.add(_pyrender_camera(crop, 1, znear, zfar), pose=_camera_pose_gl(cam_from_object))
    r = _renderer(w, h)
    flags = pyrender.RenderFlags.SHADOWS_DIRECTIONAL | pyrender.RenderFlags.SKIP_CULL_FACES
    if sun[2] <= 0.02:
        gdepth = r.render(base, flags=pyrender.RenderFlags.DEPTH_ONLY)
        return _shadow_layers(full, roi, np.ones((h, w), np.float32), gdepth)
    # pyrender's directional light shines along its node's -z axis: align -z with -sun.
    z_axis = sun
    x_axis = np.cross([0.0, 0.0, 1.0] if abs(sun[2]) < 0.99 else [1.0, 0.0, 0.0], z_axis)
    x_axis /= np.linalg.norm(x_axis)
    light_pose = np.eye(4)
    light_pose[:3, :3] = np.stack([x_axis, np.cross(z_axis, x_axis), z_axis], axis=1)
    base.add(pyrender.DirectionalLight(color=np.ones(3), intensity=3.0), pose=light_pose)
    lit, gdepth = r.render(base, flags=flags)
    mesh, mesh_pose = _to_pyrender_mesh(asset, False)
    base.add(mesh, pose=mesh_pose)
    shadowed, _ = r.render(base, flags=flags)
    # pyrender encodes output with gamma 1/2.2: decode before taking the ratio.
    lit_l = (lit[..., :3].astype(np.float32) / 255.0) ** 2.2
    sh_l = (shadowed[..., :3].astype(np.float32) / 255.0) ** 2.2
    gm = gdepth > 0
    ok = gm & (lit_l.mean(-1) > 1e-4)  # eps: ground facing away from the sun has no lit reference
    vis = np.ones((h, w), np.float32)
    vis[ok] = np.clip(sh_l.mean(-1)[ok] / lit_l.mean(-1)[ok], 0.0, 1.0)
    return _shadow_layers(full, roi, vis, gdepth)


def _shadow_layers(full: tuple | None, roi, vis: np.ndarray, gdepth: np.ndarray) -> ShadowLayers:
    """Window layers pasted into the full frame (``full`` = (H, W)), or kept as the window (``full`` None)."""
    gdepth = np.asarray(gdepth, np.float32)
    if full is None:
        return ShadowLayers(vis, gdepth > 0, gdepth, roi)
    return ShadowLayers(_paste(full, roi, vis, 1.0), _paste(full, roi, gdepth) > 0, _paste(full, roi, gdepth), roi)
