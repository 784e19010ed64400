"""Offscreen rendering: the only module that imports pyrender.

Rendering runs headless through EGL (Mesa llvmpipe on CPU). The OpenGL context is created lazily, once per process,
on first use. A process must not fork after creating it (the children hang): use ``spawn``/``forkserver`` for
worker pools that render after the parent rendered; :func:`_renderer` refuses, with a clear error, to reuse a
context inherited through fork.

Outputs are in the OpenCV camera convention of :mod:`aias_augment.geometry` with pixel centres at integer
coordinates: pyrender's window convention puts pixel centres at +0.5, which :func:`_pyrender_camera` compensates.
"""
from __future__ import annotations

import atexit
import os
from dataclasses import dataclass

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import pyrender  # noqa: E402
import trimesh  # noqa: E402

from .assets import Asset  # noqa: E402
from .geometry import Intrinsics, check_finite, check_rigid, invert_rigid, opengl_from_opencv  # noqa: E402

__all__ = ["RenderLayers", "ShadowLayers", "render_object", "render_ground_shadow", "srgb_to_linear",
           "linear_to_srgb"]

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


def _renderer(width: int, height: int) -> "pyrender.OffscreenRenderer":
    pid = os.getpid()
    if _STATE["renderer"] is not None and _STATE["pid"] != pid:
        raise RuntimeError(
            "aias_augment.render: this process was forked after its parent created an EGL renderer; rendering here "
            "would hang. Use a 'spawn' or 'forkserver' multiprocessing context (e.g. DataLoader("
            "multiprocessing_context='spawn')) or do not render in the parent before forking."
        )
    if _STATE["renderer"] is None:
        _STATE["renderer"] = pyrender.OffscreenRenderer(width, height)
        _STATE["pid"] = pid
    r = _STATE["renderer"]
    if (r.viewport_width, r.viewport_height) != (width, height):
        r.viewport_width, r.viewport_height = width, height
    return r


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding, values in [0, 1]."""
    x = np.clip(np.asarray(x, dtype=np.float32), 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(np.asarray(x, dtype=np.float32), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055).astype(np.float32)


def _pyrender_camera(intr: Intrinsics, ssaa: int, znear: float, zfar: float) -> "pyrender.IntrinsicsCamera":
    # OpenCV pixel centres are integers; OpenGL window pixel centres are at +0.5. With supersampling factor s, the
    # OpenCV coordinate u maps to s*(u + 0.5) in the big window.
    s = float(ssaa)
    return pyrender.IntrinsicsCamera(
        fx=intr.fx * s, fy=intr.fy * s, cx=(intr.cx + 0.5) * s, cy=(intr.cy + 0.5) * s, znear=znear, zfar=zfar
    )


def _camera_pose_gl(cam_from_world: np.ndarray) -> np.ndarray:
    """pyrender wants world_from_glcam."""
    return invert_rigid(opengl_from_opencv(cam_from_world))


def _downsample(x: np.ndarray, s: int) -> np.ndarray:
    if s == 1:
        return x
    h, w = x.shape[0] // s, x.shape[1] // s
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


def _to_pyrender_meshes(asset: Asset, normals: bool) -> list:
    cache_key = "_pyrender_normals" if normals else "_pyrender_albedo"
    cached = asset.meta.get(cache_key)
    if cached is not None and cached[0] == os.getpid():
        return cached[1]
    out = []
    for m in asset.meshes:
        if normals:
            n = np.asarray(m.vertex_normals, dtype=np.float64)
            colors = np.clip((n + 1.0) * 0.5 * 255.0 + 0.5, 0, 255).astype(np.uint8)
            plain = trimesh.Trimesh(m.vertices, m.faces, process=False,
                                    vertex_colors=np.c_[colors, np.full(len(colors), 255, np.uint8)])
            out.append(pyrender.Mesh.from_trimesh(plain, smooth=True))
        else:
            # Per-face colours need flat (unsmoothed) vertices in pyrender; textures and vertex colours are smooth.
            smooth = getattr(m.visual, "kind", None) != "face"
            out.append(pyrender.Mesh.from_trimesh(m, smooth=smooth))
    asset.meta[cache_key] = (os.getpid(), out)
    return out


def _render_flat(meshes: list, cam_from_object: np.ndarray, intr: Intrinsics, ssaa: int, znear: float,
                 zfar: float) -> tuple[np.ndarray, np.ndarray]:
    scene = pyrender.Scene(bg_color=np.zeros(4), ambient_light=np.ones(3))
    for m in meshes:
        scene.add(m, pose=np.eye(4))
    # Object frame is the scene's world frame.
    scene.add(_pyrender_camera(intr, ssaa, znear, zfar), pose=_camera_pose_gl(cam_from_object))
    r = _renderer(intr.width * ssaa, intr.height * ssaa)
    color, depth = r.render(scene, flags=pyrender.RenderFlags.FLAT | pyrender.RenderFlags.RGBA)
    return color, depth


def render_object(asset: Asset, cam_from_object: np.ndarray, intrinsics: Intrinsics, *, ssaa: int = 1,
                  znear: float = 0.05, zfar: float = 2000.0, with_normals: bool = True) -> RenderLayers:
    """Render ``asset`` (canonical object frame) seen by an OpenCV camera at ``cam_from_object``.

    ``ssaa``: supersampling factor (1 = aliased binary coverage, 2-4 = anti-aliased edges; cost grows as ssaa^2).
    """
    cam_from_object = check_rigid(cam_from_object, "cam_from_object")
    if ssaa < 1 or int(ssaa) != ssaa:
        raise ValueError(f"ssaa must be a positive integer, got {ssaa}")
    color, depth = _render_flat(_to_pyrender_meshes(asset, False), cam_from_object, intrinsics, ssaa, znear, zfar)
    covered = (depth > 0).astype(np.float32)
    albedo = srgb_to_linear(color[..., :3].astype(np.float32) / 255.0) * covered[..., None]
    if with_normals:
        ncol, _ = _render_flat(_to_pyrender_meshes(asset, True), cam_from_object, intrinsics, ssaa, znear, zfar)
        n_obj = ncol[..., :3].astype(np.float32) / 255.0 * 2.0 - 1.0
        n_cam = n_obj @ cam_from_object[:3, :3].T.astype(np.float32)
    else:
        n_cam = np.zeros(color.shape[:2] + (3,), np.float32)
    alpha = _downsample(covered, ssaa)
    # Average colour over covered sub-samples only (un-premultiply), z-depth: nearest covered sub-sample mean.
    w = np.maximum(alpha, 1e-6)[..., None]  # eps: avoid 0/0 where nothing is covered (result forced to 0 below)
    albedo = _downsample(albedo, ssaa) / w
    n_cam = _downsample(n_cam * covered[..., None], ssaa)
    n_len = np.linalg.norm(n_cam, axis=-1, keepdims=True)
    n_cam = np.where(n_len > 1e-6, n_cam / np.maximum(n_len, 1e-6), 0.0)
    depth_sum = _downsample(depth.astype(np.float32), ssaa)
    d = np.where(alpha > 0, depth_sum / np.maximum(alpha, 1e-6), 0.0)
    inside = alpha > 0
    albedo[~inside] = 0
    return RenderLayers(albedo.astype(np.float32), alpha.astype(np.float32), d.astype(np.float32),
                        n_cam.astype(np.float32))


@dataclass(frozen=True, eq=False)
class ShadowLayers:
    """Shadow catcher on the ground plane (z = 0 of the object frame).

    visibility: (H, W) float32 fraction of the sun visible from the ground point seen at each pixel (1 = lit), 1 where
        no ground patch was rendered.
    ground_mask: (H, W) bool, pixels where the ground patch was rendered.
    ground_depth: (H, W) float32 z-depth of the ground patch (0 outside).
    """

    visibility: np.ndarray
    ground_mask: np.ndarray
    ground_depth: np.ndarray


def _ground_patch(radius: float) -> "pyrender.Mesh":
    quad = trimesh.Trimesh(
        vertices=np.array([[-radius, -radius, 0], [radius, -radius, 0], [radius, radius, 0], [-radius, radius, 0]],
                          dtype=np.float64),
        faces=np.array([[0, 1, 2], [0, 2, 3]]), process=False,
    )
    mat = pyrender.MetallicRoughnessMaterial(baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0,
                                             roughnessFactor=1.0)
    return pyrender.Mesh.from_trimesh(quad, material=mat, smooth=False)


def render_ground_shadow(asset: Asset, cam_from_object: np.ndarray, intrinsics: Intrinsics,
                         sun_direction_in_object: np.ndarray, *, patch_radius_m: float | None = None,
                         znear: float = 0.05, zfar: float = 2000.0) -> ShadowLayers:
    """Differential shadow catcher: a Lambertian ground patch lit by the sun alone, rendered with and without the
    object; the ratio of the two (in linear radiance) is the sun visibility. ``sun_direction_in_object`` points from
    the scene toward the sun; a sun at or below the horizon (z <= 0.02) casts no shadow (visibility 1).
    """
    cam_from_object = check_rigid(cam_from_object, "cam_from_object")
    sun = check_finite(np.asarray(sun_direction_in_object, dtype=np.float64).reshape(3), "sun direction")
    norm = np.linalg.norm(sun)
    if norm < 1e-9:
        raise ValueError("sun direction has zero length")
    sun = sun / norm
    h, w = intrinsics.height, intrinsics.width
    ext = asset.extents_m
    if patch_radius_m is None:
        # Long enough for the shadow of a sun 10 deg above the horizon (cot 10deg ~ 5.7), capped for map resolution.
        patch_radius_m = float(max(ext[:2].max(), min(6.0 * ext[2], 30.0)))
    base = pyrender.Scene(bg_color=np.zeros(4), ambient_light=np.zeros(3))
    base.add(_ground_patch(patch_radius_m))
    base.add(_pyrender_camera(intrinsics, 1, znear, zfar), pose=_camera_pose_gl(cam_from_object))
    r = _renderer(w, h)
    flags = pyrender.RenderFlags.SHADOWS_DIRECTIONAL | pyrender.RenderFlags.SKIP_CULL_FACES
    if sun[2] <= 0.02:
        gdepth = r.render(base, flags=pyrender.RenderFlags.DEPTH_ONLY)
        gm = gdepth > 0
        return ShadowLayers(np.ones((h, w), np.float32), gm, gdepth.astype(np.float32))
    # pyrender's directional light shines along its node's -z axis: align -z with -sun.
    z_axis = sun
    x_axis = np.cross([0.0, 0.0, 1.0] if abs(sun[2]) < 0.99 else [1.0, 0.0, 0.0], z_axis)
    x_axis /= np.linalg.norm(x_axis)
    light_pose = np.eye(4)
    light_pose[:3, :3] = np.stack([x_axis, np.cross(z_axis, x_axis), z_axis], axis=1)
    base.add(pyrender.DirectionalLight(color=np.ones(3), intensity=3.0), pose=light_pose)
    lit, gdepth = r.render(base, flags=flags)
    for m in _to_pyrender_meshes(asset, False):
        base.add(m)
    shadowed, _ = r.render(base, flags=flags)
    # pyrender encodes output with gamma 1/2.2: decode before taking the ratio.
    lit_l = (lit[..., :3].astype(np.float32) / 255.0) ** 2.2
    sh_l = (shadowed[..., :3].astype(np.float32) / 255.0) ** 2.2
    gm = gdepth > 0
    ok = gm & (lit_l.mean(-1) > 1e-4)  # eps: ground facing away from the sun has no lit reference
    vis = np.ones((h, w), np.float32)
    vis[ok] = np.clip(sh_l.mean(-1)[ok] / lit_l.mean(-1)[ok], 0.0, 1.0)
    return ShadowLayers(vis, gm, gdepth.astype(np.float32))
