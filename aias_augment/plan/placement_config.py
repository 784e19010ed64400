"""The placement search's settings (:func:`aias_augment.plan.placement.sample_placement`): distances, pixel sizes,
the local ground refit around the contact, size targets and the scene scale of a single photo."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from aias_augment.core.config import checked_config

__all__ = ["PlacementConfig"]


# Every field is checked at construction against its type hint and these bounds (config.checked_config).
@checked_config(
    {
        "max_tries": "[1, inf)",
        "min_box_height_px": "[0, inf)",
        "max_box_height_frac": "(0, inf)",
        "max_distance_m": "(0, inf]",
        "min_distance_m": "[0, inf)",
        "max_overlap_existing": "[0, 1]",
        "min_in_image_frac": "[0, 1]",
        "depth_tolerance_rel": "(0, inf)",
        "horizon_margin_px": "[0, inf)",
        "local_radius_m": "(0, inf)",
        "local_ground_band_m": "(0, inf)",
        "local_threshold_m": "(0, inf)",
        "local_max_tilt_deg": "[0, 90]",
        "local_min_inliers": "[3, inf)",
        "local_max_depth_m": "(0, inf]",
        "local_max_points": "[3, inf)",
        "local_support_radius_m": "(0, inf)",
        "local_support_min_points": "[0, inf)",
        "local_support_max_residual_m": "(0, inf)",
        "box_height_frac_range": "(0, 1] lo<=hi",
        "box_height_frac_samples": "(0, 1]",
        "box_height_jitter": "[0, inf)",
        "box_height_tolerance": "(0, inf)",
        "camera_height_range_m": "(0, inf) lo<=hi",
        "max_pitch_turn_deg": "[0, 60]",
    },
    orders=["min_distance_m <= max_distance_m"],
)
@dataclass(frozen=True)
class PlacementConfig:
    max_tries: int = 60
    min_box_height_px: float = 12.0
    max_box_height_frac: float = 0.6  # of the image height
    max_distance_m: float = 60.0
    min_distance_m: float = 2.0
    max_overlap_existing: float = 0.3  # intersection / inserted-box area, against existing + earlier boxes
    min_in_image_frac: float = 0.9  # fraction of the projected box that must lie inside the image
    depth_tolerance_rel: float = 0.15  # |scene depth - plane depth| / plane depth for "this pixel is ground"
    horizon_margin_px: float = 8.0  # contact pixels must be this far below the horizon
    # Local ground refit around the chosen contact (needs measured points: ``points_in_cam`` or ``depth``). The
    # coarse (global) plane is only a first guess: roads are crowned and banked, sidewalks are kerb-high.
    local_refit: bool = True
    local_radius_m: float = 3.0  # refit on points within this horizontal distance of the coarse contact
    local_ground_band_m: float = 0.4  # ... and within this distance of the coarse plane (not a car trunk)
    local_threshold_m: float = 0.05  # RANSAC inlier distance of the local fit
    local_max_tilt_deg: float = 10.0  # local normal within this angle of the coarse normal
    local_min_inliers: int = 10
    local_max_depth_m: float = 40.0  # depth pixels farther than this are not used (stereo noise ~ z^2)
    local_max_points: int = 200_000  # random subset of the band points (speed)
    local_fallback: Literal["global", "reject"] = "global"  # too few points for a refit: coarse plane | reject
    # The local plane must agree with the measured points right under the object: median |residual| of the band
    # points within local_support_radius_m of the new contact <= local_support_max_residual_m. Otherwise (a kerb or a ramp
    # inside the 3 m window, where the bigger surface wins the RANSAC vote) the refit is retried with half the
    # radius, then a quarter. Fewer than local_support_min_points points there: no evidence, the plane is kept.
    local_support_radius_m: float = 1.0
    local_support_min_points: int = 5
    local_support_max_residual_m: float = 0.025  # half a kerb step; LiDAR/stereo noise (< ~3 cm sigma) passes
    # Pixel size of the inserted objects (what a detector learns from). By default a ground pixel is drawn uniformly
    # below the horizon, so sizes follow the scene's geometry. With a target, each object first draws a target box
    # height (as a fraction of the image height) from ``box_height_frac_samples`` (an empirical distribution, e.g.
    # the class's labelled boxes, jittered by ``box_height_jitter`` in log space) or uniformly from
    # ``box_height_frac_range``, and candidates are restricted to ground pixels whose predicted box height lies within
    # ``box_height_tolerance`` (relative) of it. A target the scene cannot host (ground too far or too near) falls back
    # to the 2 % of ground pixels nearest to it, and the report says so.
    box_height_frac_range: tuple[float, float] | None = None
    box_height_frac_samples: tuple[float, ...] = ()
    box_height_jitter: float = 0.1
    box_height_tolerance: float = 0.2
    # An image's existing boxes of the inserted kind (their labels name an inserted category through the taxonomy,
    # e.g. "cone" for traffic_cone, or are listed in ``size_reference_labels``) are the scene's own objects: when an
    # image has any, target box heights are drawn from theirs (jittered as above) instead of the samples/range
    # above, and an assumed-scale scene takes the scale at which objects of the category's mean height stand on
    # their bottom rows at their heights (:func:`scene_scale_from_boxes`), so an inserted object is as large as
    # the real ones on the same ground row. Images without such boxes are unaffected.
    sizes_from_existing: bool = True
    size_reference_labels: tuple[str, ...] = ()
    # An inserted object of a kind the image has labelled takes its height from one of those objects (their height
    # on the scene's ground, :func:`reference_heights_m`) times exp(N(0, reference_height_jitter)): the objects of one
    # site are mostly one model, and a same-row neighbour of another height would be a different size.
    reference_height_jitter: float = 0.06
    # A single photo's ground has no measured scale: its plane comes from a camera-height prior
    # (``GroundPlane.assumed_scale``), and a level road camera 1.65 m up cannot see a cone on the ground taller than
    # ~0.25 of the frame, while close-ups and product shots are full of them. With ``scene_scale_from_sizes`` and a
    # size target, each image first draws a reference target and a ground pixel that can host it at a camera height
    # inside ``camera_height_range_m``, and the whole scene is scaled about the camera centre to that height (the
    # one unknown a single photo leaves; every object of the image shares it, so they stay consistent with each
    # other, with the ground and with their shadows). Measured grounds (depth, LiDAR, poses) are never rescaled, and
    # without a size target nothing changes. On by default: on TraCon's dev split (2 real cone images + 60 inserted,
    # seeds 0 and 1) it raised AP50:95 from 0.191/0.089 to 0.207/0.130 (results/study_probe).
    scene_scale_from_sizes: bool = True
    camera_height_range_m: tuple[float, float] = (0.4, 4.0)
    # With two or more whole labelled objects of one inserted kind at different rows, an assumed-scale ground is
    # turned about the camera's x axis to the pitch at which objects of one height standing on their rows are their
    # boxes' heights (:func:`aias_augment.plan.references.ground_from_references`): the camera estimate of a close-up
    # looking down at cones is often far from that, and inserted objects away from the labelled ones then take the
    # wrong size. A turn beyond ``max_pitch_turn_deg`` keeps the estimate (25 deg: on 30 labelled TraCon train
    # photos 40 deg placed no more cones at the right size; studies/realism/labelled_scenes).
    pitch_from_references: bool = True
    max_pitch_turn_deg: float = 25.0
    # An inserted object of a labelled kind is rescaled about its contact point to the box height the labelled
    # objects of its kind have on its bottom row (:func:`aias_augment.plan.references.row_heights`: the line of their
    # heights against their rows, or through the ground's horizon when their rows do not spread), times the
    # reference jitter above: its neighbours' size wherever the camera estimate is wrong.
    sizes_from_rows: bool = True
