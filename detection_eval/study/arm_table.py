"""The study's arms, one table: each arm's switches of the insertion config, or the study's own flags (the config
checks its arms against it; :mod:`.arms` turns an arm into its insertion config)."""

from __future__ import annotations

# Stage switches of aias_augment.pipeline.image.InsertionConfig per arm; None = no insertion.
ARM_FLAGS: dict[str, dict | None] = {
    "original": None,
    "inserted": {},
    "naive_paste": {"naive_paste": True},
    "no_placement": {"placement": False},
    "no_shadow": {"shadow": False},
    "no_lighting": {"lighting": False},
    "no_harmonize": {"harmonize": False},
    "inserted_online": {},
    "inserted_procedural": {"asset_source": "procedural"},  # a new seeded procedural cone per object (the presets')
    # Its ablation: the category's one shared mesh (the gazebo construction cone) for every object.
    "inserted_gazebo_cone": {"asset_source": "default"},
    # Naive paste of the same family: the floor for a pipeline whose cones are procedural.
    "naive_paste_procedural": {"naive_paste": True, "asset_source": "procedural"},
    # One to three decoys per image: other road objects through the same stages, never labelled, so the insertion
    # itself (edges, shadow, harmonization) is not a sign of the class.
    "inserted_decoys": {
        "decoy_categories": ("barrel", "fire_hydrant", "concrete_block", "parking_block"),
        "decoys": (1, 3),
    },
    # The labelled objects of an image stand together as they do on roads: a row along the lane or across it, a
    # cluster, or each on its own (one of the three per image, InsertionConfig.arrangement "mixed").
    "inserted_arranged": {"arrangement": "mixed"},
    # The defaults without the exposure anchor (LightingConfig.ground_albedo_range off): what the anchor does to a
    # detector, against ``inserted``.
    "inserted_no_anchor": {"lighting_cfg": {"ground_albedo_range": None}},
    # Each object's boundary drawn from three blend modes (as rendered, hard, feathered; InsertionConfig.edge_blend),
    # so that no one kind of paste edge is the sign of a cone (Cut, Paste and Learn's blending invariance).
    "inserted_edges": {"edge_blend": ("rendered", "hard", "feather")},
    # A glossy plastic coating on every object (InsertionConfig.coating_f0 = 0.04, GGX roughness 0.4): the sky and
    # sun reflected at its surface, as real cones' PVC shows them; the defaults are matte Lambertian.
    "inserted_glossy": {"coating_f0": 0.04},
    # The defaults with the contact shadow at 0.6 instead of 0.15 (InsertionConfig.contact_shadow_strength): 0.15 is
    # nearest the real cones' base darkening (studies/lighting/contact_shadows/result); this arm asks what a detector takes
    # from a darker footprint.
    "inserted_strong_contact": {"contact_shadow_strength": 0.6},
    # The inserted image cropped, without resampling, around its largest object so that object's box height matches
    # a height drawn from the real train boxes (see closeup_crop): a level road camera ~1.65 m up cannot see a cone
    # standing on the ground taller than ~0.3 of the frame, while a third of TraCon's real cones are.
    "inserted_closeup": {"closeup_crop": True},
    # Placement fitted to the photo (in the matched-background protocol TraCon's close-ups got cones half the
    # size of their own and a third cut by the frame): box heights from the photo's own cones, objects in frame.
    "inserted_scene_sizes": {"placement_cfg": {"sizes_from_existing": True}},
    "inserted_in_frame": {"placement_cfg": {"min_in_image_frac": 1.0}},
    "inserted_scene_sizes_in_frame": {"placement_cfg": {"sizes_from_existing": True, "min_in_image_frac": 1.0}},
    # The photo's unknown metric scale (a single photo's camera height is a prior) drawn per image so that the real
    # boxes' sizes stand on its visible ground (PlacementConfig.scene_scale_from_sizes): ground contact, perspective
    # and shadows as in ``inserted``, sizes as in ``naive_paste``.
    "inserted_scene_scale": {"placement_cfg": {"scene_scale_from_sizes": True}},
    # Close-ups as the data has them: objects up to the full frame height, cut by the frame's sides or top
    # (half of the box may leave the image), the camera as low as 0.1 m and objects as near as 0.5 m, so that the
    # largest real box heights (a tenth of TraCon's cones are over 0.6 of the frame) stand on visible ground.
    "inserted_closeup_sizes": {
        "placement_cfg": {
            "max_box_height_frac": 1.0,
            "min_in_image_frac": 0.5,
            "min_distance_m": 0.5,
            "camera_height_range_m": (0.1, 4.0),
        }
    },
    # Its ablation: the assumed camera height kept, so sizes are what that height lets the visible ground host.
    "inserted_fixed_scale": {"placement_cfg": {"scene_scale_from_sizes": False}},
    # The seed's thinned subset's own real instances (aias_augment.assets.bank.lift): pasted at random positions and sizes
    # (Simple Copy-Paste, masks from the boxes by GrabCut), or lifted into 3D and inserted by the full pipeline
    # (placed on the ground, lit, shadowed, harmonized: the pipeline with the data's own appearance).
    "copy_paste": {"copy_paste": True},
    "lifted": {"lifted": True},
    # The defaults with a realism filter: a classifier fitted per seed on the thinned subset's real cone crops
    # against inserted ones scores every inserted cone, and an image whose cones look on average more inserted
    # than half the real ones is drawn again, up to this many times (aias_augment.evaluation.realism.filter.best_of;
    # the first draw is the ``inserted`` arm's).
    "inserted_filtered": {"realism_filter": 3},
    # Half the pool placed by the pipeline, half naive pastes of the same family: copy j is copy j of ``inserted``
    # or of ``naive_paste_procedural`` (same background, same draw stream), chosen by a seeded coin (see
    # pools.derive_mixed_pool). Ground context for some cones, free positions and sizes for the rest, at the same
    # amount: what mixing the two kinds of placement gives a detector, without rendering anything new.
    "inserted_mixed_naive": {"mix_pools": ("inserted", "naive_paste_procedural")},
    # The same mix as the product makes it (InsertionConfig.naive_share): each image a naive paste of the family or
    # a pipeline insertion by a uniform from its own draw stream, rendered through the image door.
    "inserted_naive_share": {"naive_share": 0.5},
}
