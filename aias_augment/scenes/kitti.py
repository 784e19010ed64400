"""KITTI odometry layouts -> Frames.

Layouts understood (``open_kitti_sequence`` detects them):
- official: ``<seq>/calib.txt`` with lines ``P0: ...`` .. ``P3: ...``, ``image_0``/``image_1`` (grey) or
  ``image_2``/``image_3`` (colour), poses in ``<seq>/poses.txt`` or ``<seq>/../../poses/<seq>.txt``;
- compact: ``calib.txt`` with two unprefixed lines (P0, P1), ``image_l``/``image_r``, ``poses.txt``
  (e.g. ``$AIAS_DATA/kitti06_seq``);
- pyslam snippet: ``KITTI04-12.yaml`` (Camera.fx.. and Camera.bf), ``kitti06-<i>[-R]-color.png``, ``06.txt``
  (e.g. ``$AIAS_DATA/kitti06_color_snippet``).

Poses: each pose line is row-major 3x4 ``world_from_cam`` of the left camera (world = left camera of frame 0).
Frames carry ``cam_from_world`` (the inverse). Baseline: ``-P1[0, 3] / P1[0, 0]`` (right camera to the right).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics, check_rigid, invert_rigid
from aias_augment.core.image_io import image_size, read_image
from aias_augment.scenes.stereo import stereo_depth

__all__ = ["KittiSequence", "open_kitti_sequence", "read_kitti_calib", "read_kitti_poses", "read_image_rgb"]


def read_image_rgb(path: Path) -> np.ndarray:
    """Any 8-bit grey/colour image file -> (H, W, 3) uint8 RGB, upright (the package's reader, 16-bit refused)."""
    return read_image(path, allow_16bit=False)


def read_projection_matrices(path: Path) -> dict[str, np.ndarray]:
    mats: dict[str, np.ndarray] = {}
    unnamed = 0
    for line in Path(path).read_text().splitlines():
        line = line.strip()
        if not line:
            continue
        m = re.match(r"^([A-Za-z_][\w]*)\s*:\s*(.*)$", line)
        name, values = (m.group(1), m.group(2)) if m else (f"P{unnamed}", line)
        if not m:
            unnamed += 1
        nums = np.array(values.split(), dtype=np.float64)
        if nums.size == 12:
            mats[name] = nums.reshape(3, 4)
    return mats


def read_pyslam_yaml(path: Path) -> dict[str, float]:
    """Flat ``Key: number`` lines of an OpenCV/pyslam settings file (its %YAML header breaks pyyaml)."""
    out = {}
    for line in Path(path).read_text().splitlines():
        m = re.match(r"^\s*([A-Za-z][\w.]*)\s*:\s*([-+0-9.eE]+)\s*(#.*)?$", line)
        if m:
            out[m.group(1)] = float(m.group(2))
    return out


def read_kitti_calib(path: str | Path, width: int, height: int, *, colour: bool = False) -> tuple[Intrinsics, float]:
    """(left intrinsics, baseline metres) from a KITTI calib.txt (P0/P1, or P2/P3 with ``colour``) or pyslam yaml."""
    path = Path(path)
    if path.suffix in (".yaml", ".yml"):
        v = read_pyslam_yaml(path)
        missing = [k for k in ("Camera.fx", "Camera.fy", "Camera.cx", "Camera.cy", "Camera.bf") if k not in v]
        if missing:
            raise ValueError(f"{path}: missing {missing}")
        intr = Intrinsics(v["Camera.fx"], v["Camera.fy"], v["Camera.cx"], v["Camera.cy"], width, height)
        return intr, v["Camera.bf"] / v["Camera.fx"]
    mats = read_projection_matrices(path)
    left, right = ("P2", "P3") if colour else ("P0", "P1")
    if left not in mats or right not in mats:
        raise ValueError(f"{path}: needs {left} and {right} (3x4 each), found {sorted(mats)}")
    intr = Intrinsics.from_matrix(mats[left][:, :3], width, height)
    # P_i = K [I | t_i]; the baseline is the x offset between the two cameras' centres.
    baseline = (mats[left][0, 3] - mats[right][0, 3]) / mats[right][0, 0]
    if not baseline > 0:
        raise ValueError(f"{path}: right camera is not to the right of the left one (baseline {baseline})")
    return intr, float(baseline)


def read_kitti_poses(path: str | Path) -> np.ndarray:
    """(N, 4, 4) world_from_cam from KITTI pose lines (12 numbers, row-major 3x4)."""
    rows = np.loadtxt(path, dtype=np.float64, ndmin=2)
    if rows.shape[1] != 12:
        raise ValueError(f"{path}: expected 12 numbers per line, got {rows.shape[1]}")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = rows.reshape(-1, 3, 4)
    for i, T in enumerate(poses):
        check_rigid(T, f"{path} line {i + 1}")
    return poses


@dataclass(frozen=True)
class KittiSequence:
    """Paths and calibration of a KITTI-layout sequence; ``frame(i)`` loads one :class:`Frame`."""

    root: Path
    intrinsics: Intrinsics
    baseline_m: float
    frame_ids: tuple[int, ...]
    left_paths: tuple[Path, ...]
    right_paths: tuple[Path | None, ...]
    world_from_cams: np.ndarray | None  # (len(frame_ids), 4, 4) or None

    def __len__(self) -> int:
        return len(self.frame_ids)

    def cam_from_world(self, i: int) -> np.ndarray | None:
        return None if self.world_from_cams is None else invert_rigid(self.world_from_cams[i])

    def stereo_depth(self, i: int, **stereo_kw) -> np.ndarray:
        if self.right_paths[i] is None:
            raise ValueError(f"frame {self.frame_ids[i]} of {self.root} has no right image")
        left = read_image(self.left_paths[i], grey=True)
        right = read_image(self.right_paths[i], grey=True)
        return stereo_depth(left, right, self.intrinsics, self.baseline_m, **stereo_kw)

    def frame(self, i: int, *, with_depth: bool = False, **stereo_kw) -> Frame:
        """Frame ``i`` (an index into ``frame_ids``); ``with_depth`` computes SGBM depth from the right image."""
        image = read_image_rgb(self.left_paths[i])
        depth = self.stereo_depth(i, **stereo_kw) if with_depth else None
        return Frame(
            image=image,
            intrinsics=self.intrinsics,
            cam_from_world=self.cam_from_world(i),
            depth=depth,
            meta={
                "source": "kitti",
                "root": str(self.root),
                "frame_id": self.frame_ids[i],
                "left_path": str(self.left_paths[i]),
                "right_path": None if self.right_paths[i] is None else str(self.right_paths[i]),
                "baseline_m": self.baseline_m,
                "depth_source": "stereo_sgbm" if with_depth else None,
            },
        )

    def frames(self, *, with_depth: bool = False, **stereo_kw) -> list[Frame]:
        return [self.frame(i, with_depth=with_depth, **stereo_kw) for i in range(len(self))]


def _open_snippet(root: Path) -> KittiSequence:
    yaml_path = next(iter(sorted(root.glob("KITTI*.yaml"))))
    lefts = {}
    for p in root.glob("kitti*-*-color.png"):
        m = re.match(r"^kitti(\d+)-(\d+)-color\.png$", p.name)
        if m:
            lefts[int(m.group(2))] = p
    if not lefts:
        raise FileNotFoundError(f"{root}: no kitti<seq>-<frame>-color.png images")
    ids = tuple(sorted(lefts))
    seq = re.match(r"^kitti(\d+)-", lefts[ids[0]].name).group(1)
    rights = tuple(
        (
            lefts[i].with_name(f"kitti{seq}-{i}-R-color.png")
            if lefts[i].with_name(f"kitti{seq}-{i}-R-color.png").exists()
            else None
        )
        for i in ids
    )
    w, h = image_size(lefts[ids[0]])
    intr, baseline = read_kitti_calib(yaml_path, w, h)
    poses_path = root / f"{seq}.txt"
    poses = None
    if poses_path.exists():
        all_poses = read_kitti_poses(poses_path)
        if max(ids) >= len(all_poses):
            raise ValueError(f"{poses_path}: {len(all_poses)} poses, frames up to {max(ids)} requested")
        # GT poses are of the grey cam0; the colour cam2 sits 6 cm to its left (KITTI P2): ignored here.
        poses = all_poses[list(ids)]
    return KittiSequence(root, intr, baseline, ids, tuple(lefts[i] for i in ids), rights, poses)


def open_kitti_sequence(
    path: str | Path, *, poses_path: str | Path | None = None, colour: bool = False
) -> KittiSequence:
    """Open any KITTI-odometry-layout sequence folder (see module doc). Raises FileNotFoundError/ValueError."""
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"not a directory: {root}")
    if not (root / "calib.txt").exists() and list(root.glob("KITTI*.yaml")):
        return _open_snippet(root)
    calib = root / "calib.txt"
    if not calib.exists():
        raise FileNotFoundError(f"{root}: no calib.txt (nor a pyslam KITTI*.yaml)")
    candidates = [("image_2", "image_3")] if colour else [("image_l", "image_r"), ("image_0", "image_1")]
    for left_dir, right_dir in candidates:
        if (root / left_dir).is_dir():
            break
    else:
        raise FileNotFoundError(f"{root}: none of {candidates} found")
    left_paths = sorted((root / left_dir).glob("*.png"))
    if not left_paths:
        raise FileNotFoundError(f"{root / left_dir}: no png images")
    ids = tuple(int(p.stem) for p in left_paths)
    right_paths = tuple(
        (root / right_dir / p.name) if (root / right_dir / p.name).exists() else None for p in left_paths
    )
    w, h = image_size(left_paths[0])
    intr, baseline = read_kitti_calib(calib, w, h, colour=colour)
    if poses_path is None:
        for cand in (root / "poses.txt", root.parent.parent / "poses" / f"{root.name}.txt"):
            if cand.exists():
                poses_path = cand
                break
    poses = None
    if poses_path is not None:
        all_poses = read_kitti_poses(poses_path)
        if max(ids) >= len(all_poses):
            raise ValueError(f"{poses_path}: {len(all_poses)} poses but image ids up to {max(ids)}")
        poses = all_poses[list(ids)]
    return KittiSequence(root, intr, baseline, ids, tuple(left_paths), right_paths, poses)
