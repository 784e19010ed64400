"""RGB-D frames with poses (NYU-Depth v2 / slambook layout) -> Frames.

Layout: ``color/<i>.png`` (RGB), ``depth/<i>.pgm`` (16-bit, ``depth_m = value / depth_scale``, 0 = unknown),
``pose.txt`` one line per frame ``tx ty tz qx qy qz qw`` = world_from_cam (OpenCV camera axes).
NYU frames have a white border from the Kinect registration: ``border_px`` pixels on each side get no depth.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics, invert_rigid, make_rigid
from aias_augment.scenes.kitti import read_image_rgb

__all__ = ["NYU_INTRINSICS", "RgbdSequence", "open_rgbd_sequence", "read_tum_poses"]

#: slambook2 ch5 / NYU-Depth v2 Kinect colour intrinsics (SOURCE.txt), 640x480.
NYU_INTRINSICS = Intrinsics(518.0, 519.0, 325.5, 253.5, 640, 480)


def read_tum_poses(path: str | Path) -> np.ndarray:
    """(N, 4, 4) world_from_cam from lines ``tx ty tz qx qy qz qw``."""
    rows = np.loadtxt(path, dtype=np.float64, ndmin=2)
    if rows.shape[1] != 7:
        raise ValueError(f"{path}: expected 7 numbers per line (tx ty tz qx qy qz qw), got {rows.shape[1]}")
    return np.stack([make_rigid(Rotation.from_quat(r[3:]).as_matrix(), r[:3]) for r in rows])


@dataclass(frozen=True)
class RgbdSequence:
    root: Path
    intrinsics: Intrinsics
    color_paths: tuple[Path, ...]
    depth_paths: tuple[Path, ...]
    world_from_cams: np.ndarray | None
    depth_scale: float = 1000.0
    border_px: int = 8

    def __len__(self) -> int:
        return len(self.color_paths)

    def frame(self, i: int) -> Frame:
        image = read_image_rgb(self.color_paths[i])
        raw = cv2.imread(str(self.depth_paths[i]), cv2.IMREAD_UNCHANGED)
        if raw is None or raw.ndim != 2:
            raise ValueError(f"{self.depth_paths[i]}: expected a single-channel depth image")
        depth = raw.astype(np.float32) / np.float32(self.depth_scale)
        b = self.border_px
        if b > 0:
            depth[:b], depth[-b:], depth[:, :b], depth[:, -b:] = 0, 0, 0, 0
        cam_from_world = None if self.world_from_cams is None else invert_rigid(self.world_from_cams[i])
        return Frame(
            image=image,
            intrinsics=self.intrinsics,
            cam_from_world=cam_from_world,
            depth=depth,
            meta={
                "source": "rgbd",
                "root": str(self.root),
                "index": i,
                "depth_source": "rgbd",
                "image_path": str(self.color_paths[i]),
            },
        )

    def frames(self) -> list[Frame]:
        return [self.frame(i) for i in range(len(self))]


def open_rgbd_sequence(
    path: str | Path, intrinsics: Intrinsics = NYU_INTRINSICS, *, depth_scale: float = 1000.0, border_px: int = 8
) -> RgbdSequence:
    root = Path(path)

    def numbered(folder: str, ext: str) -> list[Path]:
        files = [p for p in (root / folder).glob(f"*.{ext}") if p.stem.isdigit()]
        return sorted(files, key=lambda p: int(p.stem))

    colors, depths = numbered("color", "png"), numbered("depth", "pgm") or numbered("depth", "png")
    if not colors or [p.stem for p in colors] != [p.stem for p in depths]:
        raise FileNotFoundError(f"{root}: color/*.png and depth/*.pgm must exist with the same numbers")
    poses = read_tum_poses(root / "pose.txt") if (root / "pose.txt").exists() else None
    if poses is not None and len(poses) != len(colors):
        raise ValueError(f"{root}/pose.txt has {len(poses)} poses for {len(colors)} frames")
    return RgbdSequence(root, intrinsics, tuple(colors), tuple(depths), poses, depth_scale, border_px)
