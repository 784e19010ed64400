"""An object's oriented 3D box in the camera frame: what a scene's 3D labels give (the existing objects a
placement must not collide with) and what an inserted object occupies."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.core.geometry import check_rigid, transform_points

#: Unit-cube corners (x, y, z in {-0.5, 0.5}).
_UNIT_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])


@dataclass(frozen=True, eq=False)
class OrientedBox:
    """A box of ``size_xyz_m`` centred at the origin of its own frame; ``cam_from_box`` places it."""

    cam_from_box: np.ndarray
    size_xyz_m: tuple[float, float, float]
    label: str = ""

    def __post_init__(self):
        object.__setattr__(self, "cam_from_box", check_rigid(self.cam_from_box, "cam_from_box"))
        size = tuple(float(s) for s in self.size_xyz_m)
        if len(size) != 3 or not all(np.isfinite(s) and s > 0 for s in size):
            raise ValueError(f"OrientedBox.size_xyz_m must be 3 positive numbers, got {self.size_xyz_m}")
        object.__setattr__(self, "size_xyz_m", size)

    @classmethod
    def standing_on_ground(cls, cam_from_object: np.ndarray, size_xyz_m, label: str = "") -> "OrientedBox":
        """Box of an object whose frame has z up with the base at z = 0 (the project's canonical object frame)."""
        lift = np.eye(4)
        lift[2, 3] = size_xyz_m[2] / 2
        return cls(np.asarray(cam_from_object) @ lift, size_xyz_m, label)

    def corners(self) -> np.ndarray:
        """(8, 3) corners in the camera frame."""
        return transform_points(self.cam_from_box, _UNIT_CORNERS * np.asarray(self.size_xyz_m))

    def transformed(self, new_from_cam: np.ndarray) -> "OrientedBox":
        return OrientedBox(np.asarray(new_from_cam) @ self.cam_from_box, self.size_xyz_m, self.label)
