"""Camera poses of unposed photos of an object, by structure from motion (COLMAP through ``pycolmap``, on the CPU).

:func:`estimate_poses`: SIFT features, exhaustive matching and COLMAP's incremental mapper with the given pinhole
intrinsics held fixed; the largest model is kept, in COLMAP's own gauge (arbitrary origin, rotation and scale).
:func:`ground_gauge` moves it to the object's frame: z up along the normal of the dominant plane among the model's
points around the object (the floor or turntable it stands on, which must carry texture: SfM matches features, and a plain
backdrop has none), the origin on that plane under the point the cameras look at. Lengths stay in model units; the
reconstruction is scaled to metres by a reference size (the object's height). ``pycolmap`` is imported only here.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.geometry import Intrinsics, invert_rigid
from aias_augment.core.plane_fit import GroundFitError, fit_plane

__all__ = ["SfmPoses", "estimate_poses", "ground_gauge"]


@dataclass(frozen=True, eq=False)
class SfmPoses:
    """Per input image its ``cam_from_world`` (4x4, model units) or None when the mapper did not register it, the
    model's 3D points (N, 3) and their mean reprojection error (pixels)."""

    cams_from_world: tuple[np.ndarray | None, ...]
    points: np.ndarray
    mean_reprojection_error_px: float

    @property
    def registered(self) -> int:
        return sum(T is not None for T in self.cams_from_world)


def _pycolmap():
    try:
        import pycolmap
    except ImportError as exc:  # an optional extra: the posed reconstruction does not need it
        raise ImportError("unposed reconstruction needs pycolmap: pip install 'aias-augment[sfm]'") from exc
    return pycolmap


def estimate_poses(
    images_rgb: list[np.ndarray], intrinsics: Intrinsics, seed: int, workdir: str | Path | None = None
) -> SfmPoses:
    """Poses of ``images_rgb`` (all taken with ``intrinsics``) by COLMAP's incremental SfM; ``seed`` seeds its
    RANSAC and mapper (one thread: the same images give the same poses). ``workdir``: where the database and
    images go (None: a temporary folder, removed after)."""
    if len(images_rgb) < 3:
        raise ValueError(f"structure from motion needs at least 3 images, got {len(images_rgb)}")
    pycolmap = _pycolmap()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(workdir) if workdir is not None else Path(tmp)
        (work / "images").mkdir(parents=True, exist_ok=True)
        db = work / "database.db"
        db.unlink(missing_ok=True)
        names = []
        for i, img in enumerate(images_rgb):
            img = np.asarray(img)
            if img.shape[:2] != (intrinsics.height, intrinsics.width):
                raise ValueError(
                    f"image {i} is {img.shape[1]}x{img.shape[0]}, intrinsics {intrinsics.width}x{intrinsics.height}"
                )
            names.append(f"{i:05d}.png")
            cv2.imwrite(str(work / "images" / names[-1]), np.ascontiguousarray(img[:, :, ::-1]))
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = "PINHOLE"
        reader.camera_params = f"{intrinsics.fx},{intrinsics.fy},{intrinsics.cx},{intrinsics.cy}"
        extraction = pycolmap.FeatureExtractionOptions()
        extraction.num_threads = 1
        pycolmap.extract_features(
            db,
            work / "images",
            image_names=names,
            camera_mode=pycolmap.CameraMode.SINGLE,
            reader_options=reader,
            extraction_options=extraction,
            device=pycolmap.Device.cpu,
        )
        matching = pycolmap.FeatureMatchingOptions()
        matching.num_threads = 1
        pycolmap.match_exhaustive(db, matching_options=matching, device=pycolmap.Device.cpu)
        opts = pycolmap.IncrementalPipelineOptions()
        opts.ba_refine_focal_length = False
        opts.ba_refine_principal_point = False
        opts.ba_refine_extra_params = False
        opts.random_seed = int(seed)
        opts.num_threads = 1
        (work / "sparse").mkdir(exist_ok=True)
        models = pycolmap.incremental_mapping(db, work / "images", work / "sparse", options=opts)
        if not models:
            raise ValueError(
                "structure from motion registered no model (too few matched features: a textured floor helps)"
            )
        rec = max(models.values(), key=lambda r: r.num_reg_images())
        poses: list[np.ndarray | None] = [None] * len(names)
        index = {n: i for i, n in enumerate(names)}
        for im in rec.images.values():
            if im.has_pose:
                T = np.eye(4)
                T[:3] = im.cam_from_world().matrix()
                poses[index[im.name]] = T
        pts = np.array([p.xyz for p in rec.points3D.values()], float).reshape(-1, 3)
        err = float(np.mean([p.error for p in rec.points3D.values()])) if len(pts) else float("nan")
    return SfmPoses(tuple(poses), pts, err)


def ground_gauge(sfm: SfmPoses, look_at: np.ndarray, rng: np.random.Generator, object_radius: float) -> np.ndarray:
    """``object_from_model`` (4x4 rigid): z along the normal of the dominant plane among the model's points farther
    than ``object_radius`` from ``look_at`` (the floor around the object, not a face of it), toward the cameras; the
    origin on the plane under ``look_at`` (model coordinates, e.g. where the cameras' axes meet); x toward the first
    camera."""
    centres = np.array([invert_rigid(T)[:3, 3] for T in sfm.cams_from_world if T is not None])
    around = sfm.points[np.linalg.norm(sfm.points - look_at, axis=1) > object_radius]
    if len(around) < 3:
        raise ValueError("no model points around the object: the floor cannot be found")
    spread = float(np.median(np.linalg.norm(around - np.median(around, 0), axis=1)))
    # The ground fit of a scene, seen from the cameras' centroid (above the floor: the fit's origin), with up toward
    # them: the floor is the plane within 90 deg of it that holds the most points.
    eye = centres.mean(0)
    try:
        plane = fit_plane(
            around - eye, rng, up_hint=eye - look_at, max_tilt_deg=90.0, threshold_m=0.01 * spread, iterations=1000
        )
    except GroundFitError as e:
        raise ValueError(f"the floor around the object cannot be found: {e}") from e
    length = np.linalg.norm(plane.normal)  # the fit's normal is unit up to rounding: made exactly so, as d with it
    n = plane.normal / length
    d = float(plane.d / length) - float(n @ eye)
    origin = look_at - (look_at @ n + d) * n
    x = centres[0] - origin
    x = x - (x @ n) * n
    x /= max(float(np.linalg.norm(x)), 1e-12)  # eps: a camera straight above the origin
    R = np.stack([x, np.cross(n, x), n])  # rows: the object's axes in model coordinates
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ origin
    return T
