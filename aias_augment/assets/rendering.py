"""The renderer the asset tools draw with, as a type: the tools (the reconstruction's visibility and quality checks,
the bank's thumbnails) take a ``render`` callable rather than importing one, so ``assets/`` sits below ``apply/``.
:func:`aias_augment.apply.render.render_object` is the one the CLI and the tests pass.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    import numpy as np

    from aias_augment.assets.asset import Asset
    from aias_augment.core.geometry import Intrinsics

__all__ = ["ObjectLayers", "RenderObject"]


class ObjectLayers(Protocol):
    """One object's layers in one camera, each (H, W[, 3]) float32 over the full image: linear base colour,
    coverage in [0, 1], z-depth in metres (0 off the object) and unit normals in the OpenCV camera frame."""

    albedo_linear: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    normals_in_cam: np.ndarray


class RenderObject(Protocol):
    """Draw ``asset`` (its canonical object frame) seen by an OpenCV camera at ``cam_from_object`` with
    ``intrinsics``; ``ssaa`` is the supersampling factor, ``znear``/``zfar`` the clip planes in metres."""

    def __call__(
        self,
        asset: Asset,
        cam_from_object: np.ndarray,
        intrinsics: Intrinsics,
        *,
        ssaa: int = 1,
        znear: float = 0.05,
        zfar: float = 2000.0,
        with_normals: bool = True,
    ) -> ObjectLayers: ...
