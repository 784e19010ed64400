"""DGP (TRI / DDAD) scenes -> Frames with LiDAR depth, LiDAR points and existing 3D boxes in the camera frame.

Layout: ``<scene>/scene_*.json`` (samples -> datum keys; each datum has a world pose ``world_from_sensor``),
``calibration/<key>.json`` (per-sensor intrinsics, extrinsics = ``vehicle_from_sensor``), ``rgb/<CAM>/*.jpg``,
``point_cloud/LIDAR/*.npz`` (``data``: N x 4 = X, Y, Z, intensity in the LiDAR frame),
``bounding_box_3d/<CAM>/*.json`` (boxes in that camera's frame; box x = length, y = width, z = height).
Quaternions are (qw, qx, qy, qz) dicts. Camera frames are OpenCV (x right, y down, z forward).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics, invert_rigid, make_rigid, project_points, transform_points
from aias_augment.core.oriented_box import OrientedBox
from aias_augment.scenes.kitti import read_image_rgb

__all__ = ["DgpScene", "open_dgp_scene", "pose_from_json", "lidar_depth_image"]


def pose_from_json(pose: dict) -> np.ndarray:
    r, t = pose["rotation"], pose["translation"]
    R = Rotation.from_quat([r["qx"], r["qy"], r["qz"], r["qw"]]).as_matrix()
    return make_rigid(R, [t["x"], t["y"], t["z"]])


def lidar_depth_image(points_in_cam: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Sparse (H, W) float32 z-depth from points: nearest point per pixel (z-buffer), 0 where none."""
    uv, z = project_points(points_in_cam, intrinsics.K)
    ok = np.isfinite(uv).all(axis=1) & (z > 0)
    u = np.round(uv[ok, 0]).astype(np.int64)
    v = np.round(uv[ok, 1]).astype(np.int64)
    z = z[ok]
    inside = (u >= 0) & (u < intrinsics.width) & (v >= 0) & (v < intrinsics.height)
    u, v, z = u[inside], v[inside], z[inside]
    depth = np.full((intrinsics.height, intrinsics.width), np.inf, np.float32)
    np.minimum.at(depth, (v, u), z.astype(np.float32))
    depth[~np.isfinite(depth)] = 0.0
    return depth


@dataclass(frozen=True)
class DgpScene:
    root: Path
    samples: tuple[dict, ...]  # per sample: {sensor name: datum dict}
    intrinsics_by_sensor: dict  # name -> (fx, fy, cx, cy)
    vehicle_from_sensor: dict  # name -> 4x4

    @property
    def camera_names(self) -> list[str]:
        return sorted(n for n in self.samples[0] if "image" in self.samples[0][n])

    def __len__(self) -> int:
        return len(self.samples)

    def lidar_points_in_sensor(self, sample: int, lidar: str = "LIDAR") -> np.ndarray:
        datum = self.samples[sample][lidar]["point_cloud"]
        with np.load(self.root / datum["filename"]) as z:
            data = z["data"]
        if data.ndim != 2 or data.shape[1] < 3:
            raise ValueError(f"{datum['filename']}: expected N x (>=3) points, got {data.shape}")
        return data[:, :3].astype(np.float64)

    def world_from_sensor(self, sample: int, name: str) -> np.ndarray:
        datum = self.samples[sample][name]
        return pose_from_json(next(iter(datum.values()))["pose"])

    def cam_from_lidar(self, sample: int, camera: str, lidar: str = "LIDAR") -> np.ndarray:
        # Calibration (vehicle_from_sensor) and per-datum world poses agree to < 1 cm on the test scene; the
        # calibration is the static rig, so use it.
        return invert_rigid(self.vehicle_from_sensor[camera]) @ self.vehicle_from_sensor[lidar]

    def boxes_in_cam(self, sample: int, camera: str) -> list[OrientedBox]:
        ann = self.samples[sample][camera]["image"].get("annotations", {})
        # ontology key "1" = bounding_box_3d in DGP's annotation-type enum
        path = ann.get("1")
        if path is None:
            return []
        boxes = []
        for a in json.loads((self.root / path).read_text()).get("annotations", []):
            b = a["box"]
            boxes.append(
                OrientedBox(
                    pose_from_json(b["pose"]),
                    (b["length"], b["width"], b["height"]),
                    label=f"class{a.get('class_id')}#{a.get('instance_id')}",
                )
            )
        return boxes

    def frame(self, sample: int, camera: str = "CAMERA_01", lidar: str = "LIDAR") -> Frame:
        """Frame with sparse LiDAR depth; meta holds ``lidar_points_in_cam`` (N, 3) and ``boxes_in_cam``."""
        if camera not in self.samples[sample]:
            raise KeyError(f"{camera} not in sample {sample}; cameras: {self.camera_names}")
        datum = self.samples[sample][camera]["image"]
        image = read_image_rgb(self.root / datum["filename"])
        fx, fy, cx, cy = self.intrinsics_by_sensor[camera]
        intr = Intrinsics(fx, fy, cx, cy, image.shape[1], image.shape[0])
        points = transform_points(
            self.cam_from_lidar(sample, camera, lidar), self.lidar_points_in_sensor(sample, lidar)
        )
        return Frame(
            image=image,
            intrinsics=intr,
            cam_from_world=invert_rigid(self.world_from_sensor(sample, camera)),
            depth=lidar_depth_image(points, intr),
            meta={
                "source": "dgp",
                "root": str(self.root),
                "sample": sample,
                "camera": camera,
                "image_path": str(self.root / datum["filename"]),
                "depth_source": "lidar",
                "lidar_points_in_cam": points,
                "boxes_in_cam": self.boxes_in_cam(sample, camera),
                "up_in_cam": invert_rigid(self.vehicle_from_sensor[camera])[:3, :3] @ [0, 0, 1.0],
            },
        )


def open_dgp_scene(path: str | Path) -> DgpScene:
    """Open a DGP scene directory (the one holding ``scene_*.json``), or a parent with exactly one such scene."""
    root = Path(path)
    scene_jsons = sorted(root.glob("scene_*.json"))
    if not scene_jsons:
        subs = sorted(root.glob("*/scene_*.json"))
        if len(subs) != 1:
            raise FileNotFoundError(f"{root}: expected one scene_*.json (found {len(subs)} below it)")
        scene_jsons, root = subs, subs[0].parent
    scene = json.loads(scene_jsons[0].read_text())
    data_by_key = {d["key"]: d for d in scene["data"]}
    samples = []
    calib_key = None
    for s in scene["samples"]:
        calib_key = calib_key or s["calibration_key"]
        samples.append({data_by_key[k]["id"]["name"]: data_by_key[k]["datum"] for k in s["datum_keys"]})
    calib = json.loads((root / "calibration" / f"{calib_key}.json").read_text())
    intr = {}
    ext = {}
    for name, k, e in zip(calib["names"], calib["intrinsics"], calib["extrinsics"]):
        intr[name] = (k["fx"], k["fy"], k["cx"], k["cy"])
        ext[name] = pose_from_json(e)
    return DgpScene(root, tuple(samples), intr, ext)
