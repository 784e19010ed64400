"""A reconstruction measures its own quality before it is filed; below the bounds it is refused, naming the views.

- Silhouette agreement: the hull re-projected into every view (drawn by the ``render`` callable passed in) against
  that view's mask, as an IoU over the pixels farther than one voxel from the mask's boundary (the hull's surface is
  within a voxel of the silhouettes' cones, so a band of that width is discretisation, not disagreement). Views that
  agree give 1.0: measured 0.999-1.0 on a cone and a box rendered into 12 posed views at 16, 32 and 128 voxels. One
  pose moved 0.3 m carves the hull in every view (0.04-0.79); poses paired with the wrong photos (shifted by one)
  give 0.66-0.85 in the worst view. The bound, 0.9, sits between.
- Views that do not surround the object: a hull from views within a narrow cone of directions is unbounded along
  them (12 copies of one view give a sliver as long as the search box). Two views at an angle t bound a round
  object of width w to a rhombus whose long diagonal is w / sin(t / 2): 2 w at 60 degrees, the widest spread
  between two views required.
- Reprojection error, where points exist (structure from motion): COLMAP's mapper keeps observations up to 4 px;
  registered views of a rigid scene give under a pixel (0.5-0.8 px on the project's renders), a mean above 2 px is a
  model that does not fit its photos.
- Size: the filed height must lie in the category's height range of the taxonomy, widened by ``size_slack`` (1.25
  by default: a 1.09 m cone passes the 0.25-1.1 m range, a 2.7 m one does not).

Each refusal is a :class:`ReconstructionRefused` (a ``ValueError``) with the reason, the bad views and the measures.
"""

from __future__ import annotations

import numpy as np

from aias_augment.assets.rendering import RenderObject
from aias_augment.core.errors import AiasError

__all__ = [
    "ReconstructionRefused",
    "check_height",
    "check_hull",
    "check_reprojection",
    "silhouette_iou",
    "view_spread_deg",
]


class ReconstructionRefused(AiasError, ValueError):
    """A reconstruction that fails its own quality check: ``reason``, ``bad_views`` (indices into the views given)
    and ``measures`` (what was measured)."""

    def __init__(self, reason: str, bad_views: tuple[int, ...] = (), measures: dict | None = None):
        super().__init__(f"reconstruction refused: {reason}")
        self.reason, self.bad_views, self.measures = reason, tuple(bad_views), dict(measures or {})


def silhouette_iou(hull, views, voxel_m: float, *, render: RenderObject) -> np.ndarray:
    """(V,) IoU of ``hull`` (a trimesh in the views' object frame) drawn into each view by ``render`` against its mask, over the
    pixels farther than one voxel (``voxel_m`` projected at the hull's centre, at least a pixel) from the mask's
    boundary."""
    import trimesh

    from aias_augment.assets.asset import Asset
    from aias_augment.assets.view_masks import signed_distance_px as _signed_distance_px

    plain = Asset("hull", "object", (trimesh.Trimesh(hull.vertices, hull.faces, process=False),), "reconstruction")
    centre = np.asarray(hull.bounds, float).mean(axis=0)
    out = []
    for v in views:
        T = np.asarray(v.cam_from_object, float)
        drawn = render(plain, T, v.intrinsics, ssaa=1, znear=0.01, zfar=1000.0, with_normals=False).alpha > 0.5
        mask = np.asarray(v.mask, bool)
        z = max(float((T[:3, :3] @ centre + T[:3, 3])[2]), 1e-6)
        band_px = max(1.0, voxel_m * v.intrinsics.fx / z)
        care = np.abs(_signed_distance_px(mask)) > band_px
        union = ((drawn | mask) & care).sum()
        out.append(float((drawn & mask & care).sum() / union) if union else 0.0)
    return np.asarray(out)


def view_spread_deg(views, centre) -> float:
    """The widest angle, in degrees, between the directions from ``centre`` (object frame) to two views' cameras."""
    dirs = []
    for v in views:
        T = np.asarray(v.cam_from_object, float)
        d = -T[:3, :3].T @ T[:3, 3] - np.asarray(centre, float)
        dirs.append(d / max(float(np.linalg.norm(d)), 1e-12))
    D = np.asarray(dirs)
    cos = np.clip(D @ D.T, -1.0, 1.0)  # clamped before arccos: rounding can leave |cos| a hair above 1
    return float(np.degrees(np.arccos(cos.min())))


def _worst(values: np.ndarray, idx, k: int = 6) -> str:
    order = sorted(idx, key=lambda i: values[i])[:k]
    more = f" and {len(idx) - k} more" if len(idx) > k else ""
    return ", ".join(f"view {i} {values[i]:.2f}" for i in order) + more


def check_hull(hull, views, voxel_m: float, cfg, *, render: RenderObject, agreement=None) -> dict:
    """The hull's quality measures (``min_view_iou``, ``view_spread_deg``); :class:`ReconstructionRefused` naming
    the views when the views do not surround the object (``cfg.min_view_spread_deg``) or a view's silhouette IoU is
    below ``cfg.min_view_iou``. ``agreement``: a callable giving each view's leave-one-out agreement
    (:func:`aias_augment.assets.reconstruct.view_agreement`), asked only on refusal, to say which view the others
    contradict most."""
    centre = np.asarray(hull.bounds, float).mean(axis=0)
    spread = view_spread_deg(views, centre)
    if spread < cfg.min_view_spread_deg:
        raise ReconstructionRefused(
            f"the {len(views)} views see the object from within {spread:.1f} degrees of each other (views 0-"
            f"{len(views) - 1}; at least {cfg.min_view_spread_deg:g} needed): its depth is unknown; photograph it "
            "from around",
            tuple(range(len(views))),
            {"view_spread_deg": spread},
        )
    iou = silhouette_iou(hull, views, voxel_m, render=render)
    bad = [i for i in range(len(views)) if iou[i] < cfg.min_view_iou]
    measures = {"min_view_iou": round(float(iou.min()), 4), "view_spread_deg": round(spread, 1)}
    if bad:
        hint = ""
        if agreement is not None:
            agree = np.asarray(agreement())
            j = int(np.argmin(agree))
            hint = (
                f"; the others contradict view {j} most ({agree[j]:.2f} of their hull inside its mask): check its "
                "pose, its mask and which photo it belongs to"
            )
        raise ReconstructionRefused(
            f"the views disagree: the hull re-projected into {len(bad)} of {len(views)} views has a silhouette IoU "
            f"below {cfg.min_view_iou:g} ({_worst(iou, bad)}){hint}",
            tuple(bad),
            {**measures, "view_iou": [round(float(x), 4) for x in iou]},
        )
    return measures


def check_height(height_m: float, category: str, slack: float) -> list[float] | None:
    """The category's height range (the taxonomy's) the height was checked against, None for a category without
    one; :class:`ReconstructionRefused` when ``height_m`` lies outside it widened by ``slack``."""
    from aias_augment.assets.bank.taxonomy import load_taxonomy

    try:
        lo, hi = load_taxonomy().height_range_m(category)
    except KeyError:
        return None
    if not lo / slack <= height_m <= hi * slack:
        raise ReconstructionRefused(
            f"its height {height_m:.3g} m is outside {category}'s {lo:g}-{hi:g} m (x{slack:g} slack): the views, "
            "their poses or the category are wrong",
            (),
            {"height_m": height_m},
        )
    return [lo, hi]


def check_reprojection(error_px: float, bound_px: float) -> None:
    """:class:`ReconstructionRefused` when the structure-from-motion model's mean reprojection error is above the
    bound (or not a number)."""
    if not error_px <= bound_px:
        raise ReconstructionRefused(
            f"structure from motion's mean reprojection error is {error_px:.2f} px (at most {bound_px:g}): the poses do "
            "not fit the photos",
            (),
            {"sfm_reprojection_error_px": error_px},
        )
