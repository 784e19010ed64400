"""Step 2: every random draw of one insertion, as a frozen record: how many objects, which category and asset,
where each stands (a frozen :class:`~aias_augment.plan.placement.Placement`), and the harmonizer's seed.

:func:`plan_insertion` reads the :class:`SceneAnalysis` and the sample's generator only; :func:`apply_plan` then
draws nothing.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from aias_augment.analyse.analysis import SceneAnalysis
from aias_augment.analyse.instances import LabelledGround
from aias_augment.assets.asset import CATEGORY_HEIGHT_RANGE_M, DEFAULT_ASSETS, Asset, default_asset
from aias_augment.assets.deform import apply_deformation, sample_deformation
from aias_augment.core.geometry import Intrinsics, make_rigid, project_points
from aias_augment.core.oriented_box import OrientedBox
from aias_augment.core.stages import draw_frame_params, draw_layer_params
from aias_augment.plan.config import PlanConfig, plan_config
from aias_augment.plan.placement import (
    Placement,
    draw_box_height_target,
    placement_at,
    predicted_box_heights_px,
    reference_heights_m,
    sample_placement,
    scaled_ground,
    scene_scale_for_sizes,
    scene_scale_from_boxes,
)
from aias_augment.plan.references import ground_from_references, row_heights


@dataclass(frozen=True, eq=False)
class PlannedObject:
    """One object to insert: the placement record and the (scaled) asset it renders."""

    placement: Placement
    asset: Asset

    @property
    def cam_from_object(self) -> np.ndarray:
        return self.placement.cam_from_object_matrix


@dataclass(frozen=True, eq=False)
class InsertionPlan:
    """What :func:`apply_plan` does, drawn once. ``placement_reports``: per requested object, the placement
    search's report (rejections by reason). ``harmonize_seed``: seeds the harmonizer's own generator and the layer
    stages' draws. ``layer_params``: per object, ``{layer stage: its parameters}``; ``frame_params``: ``{frame stage:
    its parameters}`` (the stage list, :mod:`aias_augment.core.stages`)."""

    objects: tuple[PlannedObject, ...]
    harmonize_seed: int
    n_requested: int
    placement_reports: tuple[dict, ...] = ()
    modules: dict = field(default_factory=dict)  # e.g. 'collision': which 3D checks ran
    layer_params: tuple[dict, ...] = ()
    frame_params: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The plan as plain JSON values; ``frame_params`` only when a frame stage ran (the record of a run without
        one keeps its bytes)."""
        out = {
            "n_requested": self.n_requested,
            "harmonize_seed": self.harmonize_seed,
            "placements": [asdict(o.placement) for o in self.objects],
            "placement_reports": list(self.placement_reports),
            "modules": dict(self.modules),
            "layer_params": list(self.layer_params),
        }
        if self.frame_params:
            out["frame_params"] = dict(self.frame_params)
        return out


def plan_insertion(
    analysis: SceneAnalysis,
    cfg: PlanConfig,
    rng: np.random.Generator,
    *,
    existing_boxes_xyxy: np.ndarray | None = None,
    existing_labels: list | None = None,
    depth: np.ndarray | None = None,
    meta: dict | None = None,
    bank=None,
    n_objects: int | None = None,
    cone_looks: tuple = (),
    labelled_ground: LabelledGround | None = None,
) -> InsertionPlan:
    """Draw the insertion: ``k`` objects (``n_objects`` or uniform in [min_objects, max_objects]), each a category,
    an asset and a placement that avoids ``existing_boxes_xyxy`` (N, 4), earlier objects and, with ``meta``
    'lidar_points_in_cam' / 'boxes_in_cam', the scene's 3D points and boxes. ``depth`` (H, W) metres or None.
    ``existing_labels`` (N,): the boxes' labels; those naming an inserted category are the scene's own objects of
    that kind, which set the sizes with ``placement_cfg.sizes_from_existing`` (without labels, none does). Last, the
    plan's seed and the stage list's parameters (:mod:`aias_augment.core.stages`) from generators of their own.
    ``cone_looks``: the looks of the image's labelled cones (:func:`aias_augment.plan.looks.labelled_cone_looks`);
    with ``cone_look: labels`` procedural cones are drawn like them (the same draws of ``rng``).
    ``labelled_ground``: the ground the labelled objects stand on, by its look
    (:func:`aias_augment.analyse.instances.labelled_ground`): with ``arrangement: row``, the row's sites are on it
    (None: on the scene's placeable region, as every other object's).
    ``cfg``: the plan's record (or a config that carries one: the door's ``InsertionConfig``)."""
    if rng is None:
        raise ValueError("plan_insertion needs an explicit numpy Generator (rng) for reproducibility")
    cfg = plan_config(cfg)
    k = int(n_objects if n_objects is not None else rng.integers(cfg.min_objects, cfg.max_objects + 1))
    draft = _Draft.start(analysis, cfg, rng, existing_boxes_xyxy, existing_labels, depth, meta or {})
    draft.labelled_ground = labelled_ground
    object_cfgs = [draft.pcfg] * k
    targets = None
    if cfg.placement and draft.pcfg.scene_scale_from_sizes and k:
        # The image's targets drawn first; its scale is set by the largest (the smaller ones fit farther away).
        targets = [draw_box_height_target(draft.pcfg, rng) for _ in range(k)]
        targets = None if targets[0] is None else targets
    arrangement, line = "independent", None
    wanted = cfg.arrangement
    if wanted == "row" and cfg.placement:
        arrangement, line = "row", {"rows": {}, "used": {}}
    elif wanted != "independent" and cfg.placement and k > 1:
        arrangement = wanted
        if arrangement == "mixed":
            arrangement = ("independent", "line", "cluster")[int(rng.integers(3))]
        line = draw_arrangement(arrangement, rng, cfg)
    lead_category = None
    members = [0, []]  # [how many stood on their own for want of ground at their place, the joined objects' indices]
    for i in range(k):
        category = cfg.categories[int(rng.integers(len(cfg.categories)))]
        base = choose_asset(category, rng, cfg, bank, cone_looks)
        if cfg.deform_probability > 0 and rng.uniform() < cfg.deform_probability:
            base = apply_deformation(base, sample_deformation(base, rng, cfg.deform_cfg))
        if cfg.placement and targets is not None and i == 0:
            object_cfgs = draft.scale_scene(category, base, targets)
        near = None
        if arrangement == "row":  # the image's own row of this kind, continued (none: the object stands alone)
            near = draft.row_site_pixels(category, line)
        elif arrangement != "independent" and draft.objects and category == lead_category:
            # the leader's ground (its local refit when there was one): the arrangement lies on it. Only objects
            # of the leader's kind join it: cones line a lane, a barrel among them stands on its own.
            near = arrangement_pixels(
                draft.objects[0].placement, i, arrangement, line, analysis.intrinsics, analysis.image_shape
            )
        object_cfg = object_cfgs[i]
        if near is not None:
            # size from perspective; a row seen along its length hides part of its members behind each other
            object_cfg = replace(
                draft.pcfg,
                box_height_frac_samples=(),
                box_height_frac_range=None,
                max_overlap_existing=max(draft.pcfg.max_overlap_existing, 0.6),
            )
        placed = len(draft.objects)
        draft.place(category, base, object_cfg, decoy=False, near=near, row_site=arrangement == "row")
        if not placed:
            lead_category = category
        if near is not None:
            if len(draft.objects) > placed:
                members[1].append(placed)
                if arrangement == "row":
                    draft.take_row_site(category, line)
            else:  # no free ground at its place in the arrangement: it stands where it can on its own
                draft.place(category, base, object_cfgs[i], decoy=False)
                members[0] += 1
    if line is not None and (arrangement != "row" or any(line["rows"].values())):  # a row: when the image has one
        draft.mods["arrangement"] = _arrangement_note(arrangement, line, members)
    # Decoys: other categories through the same stages, never annotated. Drawn after the labelled objects, so these
    # draw as they would without decoys; their box heights come from the same targets as the labelled objects'.
    n_decoys = int(rng.integers(cfg.decoys[0], cfg.decoys[1] + 1)) if cfg.decoys[1] > 0 else 0
    for _ in range(n_decoys):
        category = cfg.decoy_categories[int(rng.integers(len(cfg.decoy_categories)))]
        base = choose_asset(category, rng, cfg, bank)
        pcfg = draft.pcfg
        target = draw_box_height_target(pcfg, rng) if cfg.placement else None
        object_cfg = pcfg if target is None else replace(pcfg, box_height_frac_samples=(target,), box_height_jitter=0.0)
        draft.place(category, base, object_cfg, decoy=True)
    harmonize_seed = int(rng.integers(0, 2**63 - 1))
    n = len(draft.objects)
    layer_params = draw_layer_params(cfg, harmonize_seed, n)
    frame_params = draw_frame_params(cfg, harmonize_seed)
    return InsertionPlan(
        tuple(draft.objects), harmonize_seed, k, tuple(draft.reports), draft.mods, layer_params, frame_params
    )


@dataclass(eq=False)
class _Draft:
    """A plan being drawn: the scene's ground and placement settings (the scene's scale may change them once, for
    the first object), what a new object must avoid, and the objects placed so far with the searches' reports."""

    analysis: SceneAnalysis
    cfg: PlanConfig
    rng: np.random.Generator
    depth: np.ndarray | None
    ground: object
    pcfg: object
    ref_kinds: list
    taken: list
    scene_points: np.ndarray | None
    boxes_3d: list
    mods: dict
    objects: list = field(default_factory=list)
    reports: list = field(default_factory=list)
    ref_heights: dict = field(default_factory=dict)  # per labelled kind: its objects' heights, measured once
    row_lines: dict = field(default_factory=dict)  # per labelled kind: its box height on each row (RowHeights)
    labelled_ground: LabelledGround | None = None  # the ground the labelled objects stand on, by its look

    @classmethod
    def start(cls, analysis, cfg, rng, existing_boxes_xyxy, existing_labels, depth, meta: dict) -> "_Draft":
        taken = [] if existing_boxes_xyxy is None else [np.asarray(b, float) for b in existing_boxes_xyxy]
        # DGP-style 3D scene info (meta "lidar_points_in_cam" (N, 3), "boxes_in_cam" [OrientedBox]): candidates must
        # not intersect LiDAR clusters, existing 3D boxes, or the objects inserted before them.
        scene_points = meta.get("lidar_points_in_cam")
        boxes_3d = list(meta.get("boxes_in_cam") or [])
        mods = {}
        if cfg.placement and (scene_points is not None or boxes_3d):
            mods["collision"] = (
                f"3D checks: {0 if scene_points is None else len(scene_points)} scene points, "
                f"{len(boxes_3d)} existing 3D boxes, earlier insertions"
            )
        ref_kinds = size_reference_kinds(taken, existing_labels, cfg.categories, cfg.placement_cfg)
        pcfg = scene_sized_placement(cfg.placement_cfg, [b for b, _ in ref_kinds], analysis.image_shape[0])
        if pcfg is not cfg.placement_cfg:
            mods["sizes"] = (
                f"box heights drawn from the image's {len(pcfg.box_height_frac_samples)} existing boxes of the "
                "inserted kind; an object of a labelled kind as tall as one of them on the ground"
            )
        ground = analysis.ground
        if cfg.placement and pcfg.pitch_from_references and ref_kinds:
            kinds = [k for _, k in ref_kinds]
            kind = max(set(kinds), key=lambda k: (kinds.count(k), str(k)))  # the most labelled kind: one height
            boxes = _boxes_of(ref_kinds, kind)
            turned, mods["pitch"] = ground_from_references(ground, analysis.intrinsics, boxes, pcfg.max_pitch_turn_deg)
            ground = turned if turned is not None else ground
        draft = cls(analysis, cfg, rng, depth, ground, pcfg, ref_kinds, taken, scene_points, boxes_3d, mods)
        if cfg.placement and pcfg.sizes_from_rows:
            for kind in sorted({k for _, k in ref_kinds if k is not None}):
                line, why = row_heights(ground, analysis.intrinsics, _boxes_of(ref_kinds, kind))
                mods[f"row_sizes:{kind}"] = why
                if line is not None:
                    draft.row_lines[kind] = line
        return draft

    def scale_scene(self, category: str, base: Asset, targets: list) -> list:
        """The scene's scale from the first object's size targets (or the scene's own objects on their ground rows,
        each at its kind's height): the ground and distance limits scaled with it; per object, its placement
        settings with its target."""
        ground, intr, pcfg = self.ground, self.analysis.intrinsics, self.pcfg
        hr = CATEGORY_HEIGHT_RANGE_M.get(category, (base.reference_height_m, base.reference_height_m))
        scale = None
        if self.ref_kinds:
            references = [b for b, _ in self.ref_kinds]
            heights = [_kind_height(kind, base) for _, kind in self.ref_kinds]
            scale, self.mods["scene_scale"] = scene_scale_from_boxes(ground, intr, references, np.array(heights), pcfg)
        if scale is None:
            scale, self.mods["scene_scale"] = scene_scale_for_sizes(
                ground, intr, self.rng, pcfg, float(np.mean(hr)), max(targets), self.analysis.region.mask
            )
        if scale != 1.0:  # the scene scaled about the camera: its distance limits with it
            self.ground = scaled_ground(ground, scale)
            self.pcfg = replace(
                pcfg, min_distance_m=pcfg.min_distance_m * scale, max_distance_m=pcfg.max_distance_m * scale
            )
        return [replace(self.pcfg, box_height_frac_samples=(t,), box_height_jitter=0.0) for t in targets]

    def place(self, category: str, base: Asset, object_cfg, decoy: bool, near=None, row_site: bool = False) -> None:
        """Place ``base`` (or paste it, without placement) and append it to the plan; a failed search is reported.
        ``near``: the flat indices of the pixels an arranged object may stand on (with the scene's region; sites of
        the image's labelled row, ``row_site``, below the horizon)."""
        cfg, intr = self.cfg, self.analysis.intrinsics
        if cfg.placement:
            placement = self._search(category, base, object_cfg, near, row_site and near is not None)
            if placement is None:
                return
            asset = base.scaled(placement.scale)
        else:
            hr = CATEGORY_HEIGHT_RANGE_M.get(category, (base.reference_height_m, base.reference_height_m))
            asset = base.scaled(self.rng.uniform(*hr) / base.reference_height_m)
            cam_from_object, yaw = naive_pose(asset, intr, self.rng, cfg)
            placement = replace(placement_at(asset, cam_from_object, intr, yaw), category=category)
        if asset.procedural:
            placement = replace(placement, asset_meta=_json_safe(asset.meta))
        elif "deformation" in asset.meta:  # the variant's record: a replay deforms the same source again
            placement = replace(placement, asset_meta=_json_safe({"deformation": asset.meta["deformation"]}))
        if decoy:
            placement = replace(placement, decoy=True)
        self.objects.append(PlannedObject(placement, asset))
        self.taken.append(np.array(placement.amodal_box_xyxy))
        if "collision" in self.mods:
            self.boxes_3d.append(
                OrientedBox.standing_on_ground(placement.cam_from_object_matrix, tuple(asset.extents_m), category)
            )

    def row_site_pixels(self, category: str, state: dict) -> np.ndarray | None:
        """The pixels of the free sites on the image's row of labelled ``category`` objects, continued (its sites
        beyond either end, a spacing apart, and in its gaps: :func:`labelled_row`), as ascending flat indices: every
        pixel whose ground point lies within 0.15 spacings (at least 0.1 m) of a free site, on the ground the
        labelled objects stand on when that is known (``labelled_ground``), so the placement search finds the free
        ground the row has wherever it is in view. None when the image has no such row (fewer than two labelled
        objects whose feet are seen) or no such pixel. ``state``: the plan's rows, fitted once per category, each
        with its pixels' positions along and across it, and the sites taken (:meth:`take_row_site`)."""
        if category not in state["rows"]:
            row = labelled_row(_boxes_of(self.ref_kinds, category), self.ground, self.analysis.intrinsics, self.cfg)
            if row is not None:
                row["pixels"] = self._row_frame_pixels(row)
            state["rows"][category] = row
        row = state["rows"][category]
        if row is None:
            return None
        used = state["used"].setdefault(category, set())
        free = np.array([a for j, a in enumerate(row["along"]) if j not in used])
        flat, along, across = row["pixels"]
        if not len(free) or not len(flat):
            return None
        tol = max(0.1, 0.15 * row["spacing_m"])
        gap = np.abs(along[:, None] - free[None, :]).min(axis=1)  # to the nearest free site along the line
        near = flat[np.hypot(gap, across) <= tol]
        return near if len(near) else None

    def _row_frame_pixels(self, row: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(flat indices ascending, position along the row's line, distance across it) of the pixels that may hold
        a site (:meth:`_row_windows`) whose ground point lies within a spacing of the line, on the labelled objects'
        ground (``labelled_ground``) when it is known."""
        intr = self.analysis.intrinsics
        h, w = self.analysis.image_shape
        flat = self._row_windows(row)
        if self.labelled_ground is not None:
            flat = flat[self.labelled_ground.at(flat)]
        p = self.ground.intersect_pixels(np.c_[flat % w, flat // w].astype(float), intr)
        rel = p - row["centre"]
        n, u = np.asarray(self.ground.normal, float), row["direction"]
        along = rel @ u
        across = np.linalg.norm(rel - along[:, None] * u - (rel @ n)[:, None] * n, axis=1)
        with np.errstate(invalid="ignore"):  # NaN above the horizon: not ground
            keep = (p[:, 2] > 0.5) & (across <= row["spacing_m"])
        return flat[keep], along[keep], across[keep]

    def _row_windows(self, row: dict) -> np.ndarray:
        """Ascending flat indices of the pixels in the image boxes of the row's sites: each box holds the projection
        of the square on the ground (half-side 0.15 spacings, at least 0.1 m, the sites' reach) round its site, so
        every pixel whose ground point is that near a site is in one (a projected convex square is convex); a square
        not all in front of the camera gives the whole frame."""
        intr = self.analysis.intrinsics
        h, w = self.analysis.image_shape
        n, u = np.asarray(self.ground.normal, float), row["direction"]
        v = np.cross(n, u)
        r = max(0.1, 0.15 * row["spacing_m"])
        corners = np.array([a * u + b * v for a in (-r, r) for b in (-r, r)])
        inside = np.zeros((h, w), bool)
        for a in row["along"]:
            sq = row["centre"] + a * u + corners
            if (sq[:, 2] <= 0.05).any():
                return np.arange(h * w)
            uv, _ = project_points(sq, intr.K)
            x0, y0 = np.floor(uv.min(axis=0)).astype(int)
            x1, y1 = np.ceil(uv.max(axis=0)).astype(int)
            inside[max(y0, 0) : max(min(y1 + 1, h), 0), max(x0, 0) : max(min(x1 + 1, w), 0)] = True
        return np.flatnonzero(inside)

    def take_row_site(self, category: str, state: dict) -> None:
        """Mark the site of ``category``'s row that the object placed last stands on (the site nearest its contact
        point along the row) as taken."""
        row = state["rows"].get(category)
        if row is None:
            return
        c = np.asarray(self.objects[-1].placement.contact_point_in_cam, float)
        j = int(np.argmin(np.abs(np.asarray(row["along"]) - (c - row["centre"]) @ row["direction"])))
        state["used"].setdefault(category, set()).add(j)

    def _search(self, category: str, base: Asset, object_cfg, near, row_site: bool = False) -> Placement | None:
        """The placement search for one object (its report kept), at the height of the image's labelled objects of
        its kind when there are some."""
        intr, region = self.analysis.intrinsics, self.analysis.region
        if self.ref_kinds and not self.ref_heights:
            self.ref_heights.update(_heights_by_kind(self.ref_kinds, self.ground, intr))
        heights, line = self.ref_heights.get(category), self.row_lines.get(category)
        if line is None:
            height = _height_like_references(heights, self.rng, self.pcfg.reference_height_jitter)
        else:  # sized on its row: the labelled objects' median height is where the search starts
            line = line.scaled(np.exp(self.rng.normal(0.0, self.pcfg.reference_height_jitter)))
            height = float(np.median(heights)) if heights is not None else None
        placement, report = sample_placement(
            base,
            self.ground,
            intr,
            self.rng,
            existing_boxes_xyxy=np.array(self.taken),
            depth=self.depth,
            cfg=object_cfg,
            # a row's sites on the ground its labelled objects stand on, seen by its look (the image region's road
            # appearance, seeded at the frame's bottom and eroded round every edge, leaves most of it out)
            region_mask=None if row_site and self.labelled_ground is not None else region.mask,
            within_pixels=near,
            height_range_m=CATEGORY_HEIGHT_RANGE_M.get(category),
            points_in_cam=self.scene_points,
            existing_objects=self.boxes_3d if "collision" in self.mods else None,
            object_height_m=height,
            thin_segments=region.thin_segments,
            row_heights=line,
        )
        self.reports.append(report.to_dict())
        if placement is not None and height is not None and line is None:
            placement = _box_like_references(placement, base, height, self.ground, intr)
        return placement


def draw_arrangement(kind: str, rng: np.random.Generator, cfg: PlanConfig) -> dict | None:
    """The draws of one arrangement. "line": objects at a spacing along a ground direction (its angle from the
    camera's forward direction: within 20 deg of it, a row along the road going away from the camera, or with
    probability 0.3 across it, a closure, to one side of the first), each one step from the last. "cluster": each object within
    ``arrangement_cluster_radius_m`` of the first, in a direction of its own."""
    if kind == "line":
        across = rng.uniform() < 0.3
        angle = np.deg2rad(rng.uniform(-20.0, 20.0) + (90.0 if across else 0.0))
        return {
            "angle_rad": float(angle),
            "spacing_m": float(rng.uniform(*cfg.arrangement_spacing_m)),
            "sign": float(rng.choice((-1.0, 1.0))) if across else 1.0,  # a row goes away from the camera
        }
    if kind == "cluster":
        k = cfg.max_objects
        return {
            "angles_rad": [float(a) for a in rng.uniform(-np.pi, np.pi, k)],
            "radii_m": [float(r) for r in rng.uniform(0.35, cfg.arrangement_cluster_radius_m, k)],
        }
    return None


def _arrangement_note(kind: str, params: dict, members: list) -> str:
    """The record's line for an arrangement: its draws, which objects (indices in the plan) joined the first, and
    how many stood on their own because their place in it had no free ground."""
    joined = ", ".join(str(i) for i in members[1]) or "none"
    if kind == "row":
        rows = [f"{c}: {r['n']} labelled, {r['spacing_m']:.2f} m apart" for c, r in params["rows"].items() if r]
        what, whom = "the labelled row continued (" + ("; ".join(rows) or "no labelled row") + ")", "it"
    elif kind == "line":
        way = "across the road" if abs(np.sin(params["angle_rad"])) > 0.5 else "along the road"
        what, whom = f"line {params['spacing_m']:.2f} m apart {way}", "object 0"
    else:
        what, whom = f"cluster within {max(params['radii_m']):.2f} m", "object 0"
    return f"{what}: objects [{joined}] joined {whom}, {members[0]} placed on their own (no free ground there)"


def arrangement_pixels(leader: Placement, i: int, kind: str, params: dict, intr: Intrinsics, shape) -> np.ndarray:
    """The flat indices (ascending, ``v * W + u``) of the pixels whose rays meet the leader's ground plane within a
    tenth of the spacing (0.1 m in a cluster) of where the ``i``-th object of the arrangement stands (the nearest
    pixel when none is that close; none when the point is out of view). Tested on the ground, not in the image: a
    pixel covers metres of a road seen at a grazing angle. Indices, not a mask: the window is a few hundred pixels
    of a frame the placement search has already indexed."""
    n = np.asarray(leader.ground_normal_in_cam, float)
    d_plane = float(leader.ground_d)
    p0 = np.asarray(leader.contact_point_in_cam, float)
    forward = np.array([0.0, 0.0, 1.0]) - n[2] * n  # the optical axis along the ground
    forward /= max(float(np.linalg.norm(forward)), 1e-9)  # eps: a camera looking straight down has none
    side = np.cross(n, forward)
    if kind == "line":
        a = params["angle_rad"]
        step = params["sign"] * params["spacing_m"] * i
        tol = 0.1 * params["spacing_m"]
    else:
        a = params["angles_rad"][i % len(params["angles_rad"])]
        step = params["radii_m"][i % len(params["radii_m"])]
        tol = 0.1
    p = p0 + step * (np.cos(a) * forward + np.sin(a) * side)
    return ground_window_pixels(p, n, d_plane, tol, intr, shape)


def ground_window_pixels(
    p: np.ndarray, n: np.ndarray, d_plane: float, tol: float, intr: Intrinsics, shape
) -> np.ndarray:
    """The flat indices (ascending, ``v * W + u``) of the pixels whose rays meet the plane ``n . x + d_plane = 0``
    within ``tol`` metres of its point ``p`` (the nearest pixel when none is that close; none when ``p`` is out of
    view)."""
    h, w = shape
    none = np.zeros(0, np.int64)
    if p[2] <= 0.1:
        return none
    uv, _ = project_points(p[None], intr.K)
    u, v = uv[0]
    # the window holding every pixel within tol of p: tol's image size, stretched by the grazing angle
    r = int(np.ceil(2.0 + tol * intr.fy / p[2] * max(1.0, p[2] / max(abs(d_plane), 1e-6))))  # eps: camera on plane
    x0, x1, y0, y1 = max(0, int(u) - r), min(w, int(u) + r + 1), max(0, int(v) - r), min(h, int(v) + r + 1)
    if x0 >= x1 or y0 >= y1:
        return none
    uu, vv = np.meshgrid(np.arange(x0, x1, dtype=float), np.arange(y0, y1, dtype=float))
    rays = np.stack([(uu - intr.cx) / intr.fx, (vv - intr.cy) / intr.fy, np.ones_like(uu)], -1)
    denom = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):  # rays along the plane meet it nowhere: set aside below
        t = -d_plane / denom
        dist = np.linalg.norm(rays * t[..., None] - p, axis=-1)
    dist[~(t > 0)] = np.inf
    near = dist <= tol
    if not near.any():
        if not np.isfinite(dist.min()):
            return none
        near = dist == dist.min()
    ys, xs = np.nonzero(near)  # row-major: the flat indices come out ascending
    return (ys + y0).astype(np.int64) * w + (xs + x0)


def size_references(boxes_xyxy: list, labels: list | None, categories, pcfg) -> list:
    """The boxes of ``boxes_xyxy`` that are objects of an inserted kind (:func:`size_reference_kinds`)."""
    return [b for b, _ in size_reference_kinds(boxes_xyxy, labels, categories, pcfg)]


def label_category(label: str, categories, taxonomy) -> str | None:
    """The category a label names: itself when it is one of ``categories``, else the taxonomy's class of it
    ("cone", "Traffic cone" -> traffic_cone), else None."""
    return label if label in categories else taxonomy.classify(label.replace("_", " "))


def size_reference_kinds(boxes_xyxy: list, labels: list | None, categories, pcfg) -> list[tuple]:
    """(box, category) for the boxes of ``boxes_xyxy`` that are objects of an inserted kind: their label is one of
    ``categories``, is classified into one by the taxonomy's name rules (e.g. "cone", "Traffic cone" ->
    traffic_cone) or is listed in ``pcfg.size_reference_labels`` (its category: the taxonomy's, else the inserted
    category when there is one, else None; a None label names no kind). Empty without labels or with
    ``pcfg.sizes_from_existing`` off."""
    if not pcfg.sizes_from_existing or labels is None or not len(boxes_xyxy):
        return []
    if len(labels) != len(boxes_xyxy):
        raise ValueError(f"{len(boxes_xyxy)} existing boxes but {len(labels)} labels")
    from aias_augment.assets.bank.taxonomy import load_taxonomy  # the bank package imports trimesh: only when needed

    taxonomy, cats, extra = load_taxonomy(), list(dict.fromkeys(categories)), set(map(str, pcfg.size_reference_labels))
    kinds: dict = {None: False}
    for lab in {str(x) for x in labels if x is not None}:
        named = label_category(lab, cats, taxonomy)
        if named in cats:
            kinds[lab] = named
        elif lab in extra:
            kinds[lab] = cats[0] if len(cats) == 1 else None
        else:
            kinds[lab] = False
    out = []
    for b, lab in zip(boxes_xyxy, labels):
        kind = kinds[None if lab is None else str(lab)]
        if kind is not False:
            out.append((b, kind))
    return out


def _kind_height(kind: str | None, base: Asset) -> float:
    """The height (m) a labelled object of ``kind`` is taken to have: its category's mean height; ``base``'s
    (the first object drawn) for a kind without a known range."""
    hr = CATEGORY_HEIGHT_RANGE_M.get(kind) if kind is not None else None
    return float(np.mean(hr)) if hr is not None else float(base.reference_height_m)


def labelled_feet(boxes_xyxy: np.ndarray, ground, intr: Intrinsics) -> np.ndarray:
    """(K, 3) where the labelled objects ``boxes_xyxy`` (M, 4) stand on ``ground``: each box's bottom centre on the
    plane (its object's nearest edge), moved half the box's width (in metres there) away from the camera; boxes cut
    by the image's bottom edge, or whose bottom is not on the ground in front of the camera, left out."""
    boxes = np.asarray(boxes_xyxy, float).reshape(-1, 4)
    boxes = boxes[boxes[:, 3] < intr.height - 2]
    if not len(boxes):
        return np.zeros((0, 3))
    n = np.asarray(ground.normal, float)
    near_edge = ground.intersect_pixels(np.c_[(boxes[:, 0] + boxes[:, 2]) / 2, boxes[:, 3]], intr)
    ok = np.all(np.isfinite(near_edge), axis=1) & (near_edge[:, 2] > 0.5)
    near_edge, boxes = near_edge[ok], boxes[ok]
    away = near_edge + float(ground.d) * n  # from the camera's foot on the plane
    away /= np.maximum(np.linalg.norm(away, axis=1, keepdims=True), 1e-9)  # eps: a box right below the camera
    half_m = (boxes[:, 2] - boxes[:, 0]) / 2 * near_edge[:, 2] / intr.fx
    return near_edge + half_m[:, None] * away


def labelled_row(boxes_xyxy: np.ndarray, ground, intr: Intrinsics, cfg: PlanConfig, ends: int = 3) -> dict | None:
    """The row the labelled objects ``boxes_xyxy`` (M, 4) stand in, on ``ground``: their feet (the boxes' bottom
    centres on the plane, moved half the box's width away from the camera; boxes cut by the image's bottom edge
    left out), the line through them (their principal direction on the plane), the spacing (the smallest gap
    between neighbours along it, within ``cfg.arrangement_spacing_m`` widened to 0.5-4 m) and the sites that
    continue it (``along``: their positions on the line from ``centre`` in ``direction``): 1 to ``ends`` spacings
    beyond each end (most of a row's continuation is out of a close-up's view: the placement search takes those in
    view), evenly in every gap over 1.6 spacings (a gap of more than ``2 ends + 1`` spacings: ``ends`` from each
    side). None with fewer than two feet on the ground."""
    feet = labelled_feet(boxes_xyxy, ground, intr)
    if len(feet) < 2:
        return None
    n = np.asarray(ground.normal, float)
    centre = feet.mean(axis=0)
    flat = (feet - centre) - np.outer((feet - centre) @ n, n)  # on the plane
    u = np.linalg.svd(flat, full_matrices=False)[2][0]
    u = u - (u @ n) * n
    u /= max(float(np.linalg.norm(u)), 1e-9)  # eps: feet on one point have no direction (svd gives some unit)
    t = np.sort(flat @ u)
    gaps = np.diff(t)
    lo, hi = min(0.5, cfg.arrangement_spacing_m[0]), max(4.0, cfg.arrangement_spacing_m[1])
    spacing = float(np.clip(gaps.min(), lo, hi))  # the closest pair: a gap in the row is a missing object
    along = [t[-1] + j * spacing for j in range(1, ends + 1)] + [t[0] - j * spacing for j in range(1, ends + 1)]
    for a, b in zip(t[:-1], t[1:]):  # a gap of m + 1 spacings (rounded) misses m objects, evenly spaced in it
        m = int(round((b - a) / spacing)) - 1 if b - a > 1.6 * spacing else 0
        if m <= 2 * ends:
            along += [a + (b - a) * k / (m + 1) for k in range(1, m + 1)]
        else:  # a long gap (two groups of one row): each group continued into it, as the ends are
            along += [a + k * spacing for k in range(1, ends + 1)] + [b - k * spacing for k in range(1, ends + 1)]
    along = [a for a in along if (centre + a * u)[2] > 0.5]  # in front of the camera
    if not along:
        return None
    return {"n": len(feet), "spacing_m": spacing, "centre": centre, "direction": u, "along": along}


def _boxes_of(ref_kinds: list[tuple], kind) -> np.ndarray:
    """(M, 4) xyxy: the image's labelled boxes of ``kind``."""
    return np.array([b for b, k in ref_kinds if k == kind])


def _heights_by_kind(ref_kinds: list[tuple], ground, intr: Intrinsics) -> dict:
    """{category: (M,) heights in metres of the image's labelled objects of it on ``ground``} (whole boxes only)."""
    boxes = np.array([b for b, _ in ref_kinds], float).reshape(-1, 4)
    heights = reference_heights_m(ground, intr, boxes)
    out: dict = {}
    for h, (_, kind) in zip(heights, ref_kinds):
        if kind is not None and np.isfinite(h) and h > 0:
            out.setdefault(kind, []).append(float(h))
    return {k: np.array(v) for k, v in out.items()}


def _height_like_references(heights: np.ndarray | None, rng: np.random.Generator, jitter: float) -> float | None:
    """A height near one of the labelled objects' ``heights`` (M,) (log-normal jitter), or None without any."""
    if heights is None or not len(heights):
        return None
    return float(heights[int(rng.integers(len(heights)))] * np.exp(rng.normal(0.0, jitter)))


def scene_sized_placement(pcfg, existing_xyxy: list, image_height: int):
    """``pcfg`` with its box-height samples taken from the existing boxes (heights / image height) when
    ``pcfg.sizes_from_existing`` and the image has boxes of positive height; else ``pcfg`` itself."""
    if not pcfg.sizes_from_existing or not existing_xyxy:
        return pcfg
    b = np.asarray(existing_xyxy, float).reshape(-1, 4)
    fr = (b[:, 3] - b[:, 1]) / float(image_height)
    fr = fr[np.isfinite(fr) & (fr > 0) & (fr <= 1)]
    return pcfg if len(fr) == 0 else replace(pcfg, box_height_frac_samples=tuple(float(f) for f in fr))


def _json_safe(x):
    """``x`` with numpy scalars/arrays and tuples turned into plain JSON types (an asset's meta for the record)."""
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_json_safe(v) for v in x]
    return x.item() if isinstance(x, np.generic) else x


def naive_pose(asset: Asset, intr: Intrinsics, rng, cfg: PlanConfig) -> tuple[np.ndarray, float]:
    """Random 2D position and size with no scene geometry: the object stands upright facing the camera at the
    depth that gives the sampled pixel height, centred on a random pixel."""
    if cfg.naive_height_frac_samples:  # the same empirical size distribution the placement targets use
        base = cfg.naive_height_frac_samples[int(rng.integers(len(cfg.naive_height_frac_samples)))]
        h_px = (
            float(np.clip(base * np.exp(rng.normal(0.0, cfg.placement_cfg.box_height_jitter)), 1e-3, 1.0)) * intr.height
        )
    else:
        h_px = rng.uniform(*cfg.naive_height_frac_range) * intr.height
    z = intr.fy * asset.height_m / h_px
    u = rng.uniform(0.1, 0.9) * intr.width
    v = rng.uniform(0.1, 0.9) * intr.height
    yaw = rng.uniform(-np.pi, np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    R_up = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # object z (up) -> camera -y
    R_yaw = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    centre_cam = np.array([(u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z])
    t = centre_cam - R_up @ R_yaw @ np.array([0, 0, asset.height_m / 2])
    return make_rigid(R_up @ R_yaw, t), yaw


def choose_asset(category: str, rng, cfg: PlanConfig, bank=None, cone_looks: tuple = ()) -> Asset:
    """The caller's asset source, else a new seeded procedural asset (asset_source "procedural", categories with a
    generator: :data:`aias_augment.assets.bank.procedural.CATEGORY_SPECS`), else the shared-data default of the category
    (asset_source "default"; "procedural" for other categories), else the asset bank (``aias_augment.assets.bank``:
    sweethome3d catalogs, gazebo models, procedural debris), real-size jittered. A procedural cone is drawn like one
    of ``cone_looks`` (the image's labelled cones) with ``cone_look: labels``."""
    if bank is not None:
        return bank.sample(category, rng)
    if cfg.asset_source == "procedural":
        from aias_augment.assets.bank.procedural import CATEGORY_SPECS, procedural_asset

        if category in CATEGORY_SPECS and cfg.family_members is not None:  # one draw of rng: the member index
            from aias_augment.assets.bank.family_cache import default_family

            return default_family(category, cfg.family_members, cfg.family_seed).sample(rng)
        if category == "traffic_cone" and cone_looks and cfg.cone_look == "labels":  # one draw: its seed
            from aias_augment.assets.bank.procedural import procedural_asset_like

            return procedural_asset_like(category, rng, cone_looks)
        if category in CATEGORY_SPECS:  # a new seeded one per object (one draw of rng: its seed)
            return procedural_asset(category, rng)
    if cfg.asset_source in ("default", "procedural") and category in DEFAULT_ASSETS:
        return default_asset(category)
    from aias_augment.assets.bank import get_bank  # lazy: the bank catalog is only read when a category needs it

    return get_bank().sample(category, rng)


def _box_like_references(placement: Placement, base: Asset, height_m: float, ground, intr: Intrinsics) -> Placement:
    """``placement`` rescaled about its contact point so that its box is as tall as a labelled object's box on the
    same row. The labelled objects' heights are measured as vertical segments on their boxes' bottom rows, but a
    box also holds the object's footprint (its base seen from above: much of a cone's box when the camera looks
    down), so an object of the measured height has a taller box than its neighbours; two fixed-point steps shrink it
    to the segment's height at its own bottom row (no draw)."""
    for _ in range(2):
        x0, _, x1, y1 = placement.amodal_box_xyxy
        target = float(predicted_box_heights_px(np.array([[(x0 + x1) / 2, y1]]), height_m, ground, intr)[0])
        box_h = placement.amodal_box_xyxy[3] - placement.amodal_box_xyxy[1]
        if not (np.isfinite(target) and target > 0 and box_h > 0) or abs(target / box_h - 1.0) < 0.01:
            break
        asset = base.scaled(placement.scale * target / box_h)
        again = placement_at(asset, np.asarray(placement.cam_from_object_matrix), intr, placement.yaw_rad, ground)
        placement = replace(
            placement,
            scale=again.scale,
            height_m=again.height_m,
            amodal_box_xyxy=again.amodal_box_xyxy,
            box_in_object_m=again.box_in_object_m,
        )
    return placement
