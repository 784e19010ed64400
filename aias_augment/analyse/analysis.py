"""Step 1: what the scene offers, computed once per frame (camera and horizon, ground plane, placeable region,
lighting) and, per module, what was used or "skipped: why".

:func:`analyse_scene` is a pure function of the frame (image, K, depth, semantics, metadata) and of the few config
fields it reads (:meth:`~aias_augment.analyse.config.AnalyseConfig.key_fields`): its random draws (RANSAC, pixel subsampling) come from a
generator with a fixed seed, never from the sample's. So the result is cached by :func:`scene_key` (``cache.py``).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import xxhash

from aias_augment.analyse.config import AnalyseConfig, analyse_config
from aias_augment.analyse.exposure import ExposureMatch
from aias_augment.analyse.ground import GroundFitError, GroundPlane, ground_plane_from_depth, prior_ground_plane
from aias_augment.analyse.lighting.estimate import LightingEstimate, estimate_lighting
from aias_augment.analyse.region import PlaceableRegion, below_horizon_mask, placeable_region
from aias_augment.analyse.single_image import SingleImageConfig, estimate_camera_from_image
from aias_augment.analyse.thin_structures import thin_structure_segments
from aias_augment.core.envmap import EnvironmentMap
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.report import skipped

#: Bumped whenever what analyse_scene computes changes: on-disk cache entries of another version are not read.
ANALYSIS_VERSION = "5"  # the record's format: a cached analysis of another version is computed again
#                        cameras are recorded (modules["colour"]) and their insertions rendered as luminance
#: Seed of the analysis' own generator (the analysis must not depend on the sample's random stream).
ANALYSIS_SEED = 20240614
#: meta keys that are sample/plan inputs, not scene analysis inputs (not part of the cache key).
PLAN_META_KEYS = ("lidar_points_in_cam", "boxes_in_cam")


@dataclass(frozen=True, eq=False)
class SceneAnalysis:
    """Everything about one frame that does not depend on the sample.

    intrinsics: the camera used (given, estimated or prior). ground: the ground plane (None when placement is off).
    region: where objects may stand (None when placement is off). lighting: sun + SH ambient in the image's linear
    units. modules: per module ('mode', 'camera', 'ground', 'placement', 'region', 'lighting') what was used, or
    "skipped: why", for people. key: the frame's :func:`scene_key`. monochrome: the frame comes from a monochrome
    camera (inserted objects are written as its luminance).
    """

    key: str
    image_shape: tuple[int, int]
    intrinsics: Intrinsics
    ground: GroundPlane | None
    region: PlaceableRegion | None
    lighting: LightingEstimate
    modules: dict = field(default_factory=dict)
    monochrome: bool = False

    def to_dict(self) -> dict:
        """JSON-ready (the region mask is left out: :meth:`save` writes it beside)."""
        g = self.ground
        return {
            "version": ANALYSIS_VERSION,
            "key": self.key,
            "image_shape": list(self.image_shape),
            "intrinsics": [
                self.intrinsics.fx,
                self.intrinsics.fy,
                self.intrinsics.cx,
                self.intrinsics.cy,
                self.intrinsics.width,
                self.intrinsics.height,
            ],
            "ground": None
            if g is None
            else {
                "normal": g.normal.tolist(),
                "d": g.d,
                "source": g.source,
                "inlier_ratio": g.inlier_ratio,
                "rms_m": g.rms_m,
                "num_inliers": g.num_inliers,
                "assumed_scale": g.assumed_scale,
            },
            "region": None if self.region is None else self.region.to_dict(),
            "lighting": self.lighting.to_dict(),
            "modules": dict(self.modules),
            "monochrome": self.monochrome,
        }

    def save(self, path: str | Path) -> None:
        """One ``.npz``: the JSON record and the region mask (written atomically: a killed run leaves no half file)."""
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp.npz")
        mask = np.zeros((0, 0), bool) if self.region is None else np.asarray(self.region.mask, bool)
        np.savez_compressed(tmp, record=np.array(json.dumps(self.to_dict())), region_mask=mask)
        tmp.replace(path)

    @classmethod
    def load(cls, path: str | Path) -> "SceneAnalysis":
        with np.load(path, allow_pickle=False) as z:
            d = json.loads(str(z["record"]))
            mask = z["region_mask"]
        if d.get("version") != ANALYSIS_VERSION:
            raise ValueError(f"scene analysis {path}: version {d.get('version')} != {ANALYSIS_VERSION}")
        fx, fy, cx, cy, w, h = d["intrinsics"]
        g = d["ground"]
        ground = (
            None
            if g is None
            else GroundPlane(
                np.array(g["normal"]),
                g["d"],
                g["source"],
                g["inlier_ratio"],
                g["rms_m"],
                g["num_inliers"],
                g["assumed_scale"],
            )
        )
        r = d["region"]
        region = (
            None
            if r is None
            else PlaceableRegion(
                mask.astype(bool),
                r["evidence"],
                r["fraction"],
                r.get("excluded", {}),
                np.array(r.get("thin_segments", []), np.float32).reshape(-1, 4),
            )
        )
        L = d["lighting"]
        lighting = LightingEstimate(
            None if L["sun_direction_in_cam"] is None else np.array(L["sun_direction_in_cam"]),
            np.array(L["sun_irradiance_rgb"]),
            np.array(L["ambient_sh"]),
            L["sun_sky_ratio"],
            L["dominant_sun"],
            L["confidence"],
            L["source"],
            np.array(L["up_in_cam"]),
        )
        return cls(
            d["key"],
            tuple(d["image_shape"]),
            Intrinsics(fx, fy, cx, cy, int(w), int(h)),
            ground,
            region,
            lighting,
            d["modules"],
            d["monochrome"],
        )


def hash_value(h, v) -> None:
    if v is None:
        h.update(b"None")
    elif isinstance(v, np.ndarray) or (isinstance(v, (list, tuple)) and v and isinstance(v[0], np.ndarray)):
        a = np.ascontiguousarray(np.asarray(v))
        h.update(f"{a.dtype}{a.shape}".encode())
        try:
            h.update(memoryview(a).cast("B"))  # the same bytes as a.tobytes(), without the copy
        except (TypeError, ValueError):  # object / odd buffer formats
            h.update(a.tobytes())
    elif isinstance(v, Intrinsics):
        h.update(repr((v.fx, v.fy, v.cx, v.cy, v.width, v.height)).encode())
    elif isinstance(v, EnvironmentMap):  # a scene fact: by its pixels and orientation (its repr elides them)
        h.update(b"EnvironmentMap")
        hash_value(h, v.radiance)
        hash_value(h, np.asarray(v.world_from_env, np.float64))
    else:
        h.update(repr(v).encode())


_CFG_BYTES: dict = {}


def _cfg_bytes(cfg: AnalyseConfig) -> bytes:
    """What the key hashes of ``cfg``: the repr of its sorted analysis fields (a frozen config: memoised by
    identity, the memo holding the config so that its id is not reused)."""
    got = _CFG_BYTES.get(id(cfg))
    if got is None or got[0] is not cfg:
        if len(_CFG_BYTES) > 64:
            _CFG_BYTES.clear()
        got = _CFG_BYTES[id(cfg)] = (cfg, repr(sorted(cfg.key_fields().items())).encode())
    return got[1]


def scene_key(frame: Frame, cfg: AnalyseConfig) -> str:
    """xxh3-128 (hex) of what :func:`analyse_scene` reads: image bytes, K, depth, semantics, scene meta, the config
    fields it uses and the analysis version. Not sha256: every call hashes the image (640x480: 0.03 ms against
    0.6 ms); 128 bits make an accidental collision negligible (a cache of your own data, not a defence against
    crafted inputs)."""
    h = xxhash.xxh3_128(f"aias-scene-analysis v{ANALYSIS_VERSION}".encode())
    for name, v in (
        ("image", frame.image),
        ("K", frame.intrinsics),
        ("depth", frame.depth),
        ("semantic", frame.semantic),
    ):
        h.update(name.encode())
        hash_value(h, v)
    h.update(b"cfg")
    h.update(_cfg_bytes(analyse_config(cfg)))
    for k in sorted(frame.meta):
        if k not in PLAN_META_KEYS:
            h.update(f"meta:{k}".encode())
            hash_value(h, frame.meta[k])
    return h.hexdigest()


def analyse_scene(frame: Frame, cfg: AnalyseConfig = AnalyseConfig(), *, key: str | None = None) -> SceneAnalysis:
    """Camera, ground, placeable region and lighting of ``frame`` (see the module docstring). ``key``: the frame's
    :func:`scene_key` when the caller computed it already. ``cfg``: the analysis' record, or a config that carries
    one (the door's ``InsertionConfig``: its ``analyse``)."""
    cfg = analyse_config(cfg)
    img = frame.image
    h, w = img.shape[:2]
    meta = dict(frame.meta)
    if frame.semantic is not None and meta.get("semantic") is None:
        meta["semantic"] = frame.semantic
    rng = np.random.default_rng(ANALYSIS_SEED)
    mods: dict = {}
    if cfg.naive_paste:
        mods["mode"] = "naive paste: random position/scale, no geometry/lighting/shadow/harmonization"
    given_K = frame.intrinsics
    if given_K is not None and not isinstance(given_K, Intrinsics):
        given_K = Intrinsics.from_matrix(np.asarray(given_K), w, h)
    # The camera's copy is at least camera_analysis_width wide: on a 160 px copy the roll can be off by 20 deg.
    cheap = 0 < cfg.analysis_max_width < w
    small = _analysis_copy(img, max(cfg.analysis_max_width, cfg.camera_analysis_width)) if cheap else None
    if small is None or frame.depth is not None:  # depth: the ground comes from it, at its own resolution
        intr, ground = scene_geometry(img, given_K, frame.depth, rng, cfg, mods, need_ground=cfg.placement)
    else:
        sh_, sw_ = small.shape[:2]
        intr_s, ground = scene_geometry(
            small,
            None if given_K is None else _scaled_intrinsics(given_K, sw_, sh_),
            None,
            rng,
            cfg,
            mods,
            need_ground=cfg.placement,
        )
        intr = given_K if given_K is not None else _scaled_intrinsics(intr_s, w, h)
    if not cfg.placement:
        mods["placement"] = skipped("disabled (ablation or naive paste); random 2D position and size")
    region = None
    if cfg.placement:
        if meta.get("placeable_mask") is not None:  # the caller says where objects may stand (e.g. road pixels)
            m = np.asarray(meta["placeable_mask"], bool)
            if m.shape != (h, w):
                raise ValueError(f"meta['placeable_mask'] must be {(h, w)}, got {m.shape}")
            region = PlaceableRegion(m & below_horizon_mask(ground, intr), "given", float(m.mean()))
        else:
            region = placeable_region(intr, ground, depth=frame.depth, semantic=meta.get("semantic"), image=img)
        mods["region"] = f"{region.evidence} ({100 * region.fraction:.0f}% of the image placeable)"
        if region.excluded:
            mods["region"] += ", excluded: " + ", ".join(f"{k} {100 * v:.0f}%" for k, v in region.excluded.items())
        if cfg.thin_structures:
            region = dataclasses.replace(region, thin_segments=thin_structure_segments(img, region.mask))
            mods["region"] += f"; {len(region.thin_segments)} thin structures off the ground (poles, rails)"
        # measured regions only: the image region leaves cast shadows out, it would bias the sun/sky ratio
        if region.measured and "ground_mask" not in meta:
            meta["ground_mask"] = region.mask  # lit/shadowed ground for the sun/sky ratio
    up_ground = ground or prior_ground_plane(cfg.camera_height_m)
    # The lighting's copy is at least lighting_cfg.min_input_width wide (the camera's may be narrower): on a 160 px
    # copy the sun's side and the cast-shadow contrast are lost (studies/lighting/kitti_cast_shadow/result/kitti_cast_shadow.md).
    lsmall = _analysis_copy(img, max(cfg.analysis_max_width, cfg.lighting_cfg.min_input_width)) if cheap else None
    if lsmall is None:
        lighting = scene_lighting(img, intr, up_ground, cfg, meta, mods)
    else:
        sh_, sw_ = lsmall.shape[:2]
        meta_s = dict(meta)
        for k in ("ground_mask", "semantic"):  # per-pixel inputs follow the copy (nearest: labels stay labels)
            if meta_s.get(k) is not None:
                rows = ((np.arange(sh_) + 0.5) * h / sh_).astype(int)
                cols = ((np.arange(sw_) + 0.5) * w / sw_).astype(int)
                meta_s[k] = np.asarray(meta_s[k])[rows][:, cols]
        lighting = scene_lighting(lsmall, _scaled_intrinsics(intr, sw_, sh_), up_ground, cfg, meta_s, mods)
    monochrome = is_monochrome(img)
    if monochrome:
        mods["colour"] = (
            "monochrome camera (R = G = B in the image): inserted objects are written as luminance, "
            "as this camera sees them"
        )
    if cheap:
        lw = f"{lsmall.shape[1]}x{lsmall.shape[0]} copy" if lsmall is not None else "the full image"
        cw = f"a {small.shape[1]}x{small.shape[0]} copy" if small is not None else "the full image"
        mods["analysis"] = (
            f"cheap: camera{'' if frame.depth is None else ' (not: depth given)'} estimated on "
            f"{cw} of the {w}x{h} image (analysis_max_width "
            f"{cfg.analysis_max_width}, camera_analysis_width {cfg.camera_analysis_width}), lighting on {lw} "
            f"(lighting_cfg.min_input_width "
            f"{cfg.lighting_cfg.min_input_width}); region at full resolution"
        )
    return SceneAnalysis(key or scene_key(frame, cfg), (h, w), intr, ground, region, lighting, mods, monochrome)


def is_monochrome(image: np.ndarray, tol: int = 2, min_fraction: float = 0.99) -> bool:
    """Whether an RGB uint8 image comes from a monochrome camera (a grey image stored as RGB): on a regular sample of
    its pixels (every 4th row and column), at least ``min_fraction`` have their three channels within ``tol``
    levels of each other (JPEG chroma noise stays within it; a colour photo of a grey road does not: sky, paint,
    foliage and lamps are coloured)."""
    s = np.asarray(image)[::4, ::4].astype(np.int16)
    if s.ndim != 3 or s.shape[2] != 3 or s.size == 0:
        return False
    d = np.maximum(np.abs(s[..., 0] - s[..., 1]), np.abs(s[..., 1] - s[..., 2]))
    return bool(np.mean(d <= tol) >= min_fraction)


def _analysis_copy(image: np.ndarray, max_width: int) -> np.ndarray | None:
    """The image shrunk (area average) to ``max_width`` pixels wide, or None when it is not wider (or 0)."""
    h, w = image.shape[:2]
    if not max_width or w <= max_width:
        return None
    sw = int(max_width)
    sh = max(1, int(round(h * sw / w)))
    return cv2.resize(image, (sw, sh), interpolation=cv2.INTER_AREA)


def _scaled_intrinsics(K: Intrinsics, width: int, height: int) -> Intrinsics:
    """``K`` for the same camera at ``width`` x ``height`` (pixel centres at integers: c' = (c + 0.5) s - 0.5)."""
    sx, sy = width / K.width, height / K.height
    return Intrinsics(K.fx * sx, K.fy * sy, (K.cx + 0.5) * sx - 0.5, (K.cy + 0.5) * sy - 0.5, int(width), int(height))


def scene_geometry(
    image: np.ndarray, intrinsics, depth, rng, cfg: AnalyseConfig, modules: dict, need_ground: bool
) -> tuple[Intrinsics, GroundPlane | None]:
    """Camera and ground plane from what the scene offers: depth (RANSAC) > vanishing lines in the image (horizon,
    pitch, roll, focal when unknown) > priors (FOV, level camera at the configured height)."""
    h, w = image.shape[:2]
    if intrinsics is not None and not isinstance(intrinsics, Intrinsics):
        intrinsics = Intrinsics.from_matrix(np.asarray(intrinsics), w, h)
    modules["camera"] = "given" if intrinsics is not None else "unknown"
    if not need_ground:
        if intrinsics is None:
            modules["camera"] = f"prior: hfov {cfg.default_hfov_deg} deg (no placement: only the size matters)"
            intrinsics = Intrinsics.from_fov(w, h, cfg.default_hfov_deg)
        return intrinsics, None
    if depth is not None and intrinsics is not None:
        try:
            g = ground_plane_from_depth(depth, intrinsics, rng)
            modules["ground"] = f"RANSAC on depth ({g.inlier_ratio:.2f} inliers, rms {g.rms_m:.3f} m)"
            return intrinsics, g
        except GroundFitError as e:
            modules["ground"] = f"depth fit failed ({e}); "
    elif depth is not None:
        modules["ground"] = "depth ignored: no intrinsics to unproject it; "
    if cfg.estimate_camera:
        cam = estimate_camera_from_image(
            image,
            rng,
            intrinsics=intrinsics,
            cfg=SingleImageConfig(hfov_prior_deg=cfg.default_hfov_deg, camera_height_m=cfg.camera_height_m),
        )
        pitch, roll = (np.degrees(x) for x in cam.ground.pitch_roll_rad())
        if abs(pitch) <= cfg.max_camera_pitch_deg and abs(roll) <= cfg.max_camera_roll_deg:
            if intrinsics is None:
                modules["camera"] = f"estimated: focal from {cam.focal_source}"
            modules["ground"] = modules.get("ground", "") + (
                f"horizon from {cam.horizon_source} (pitch {pitch:.1f}, roll {roll:.1f} deg), camera "
                f"{cfg.camera_height_m} m above the ground (prior)"
            )
            return cam.intrinsics, cam.ground
        # A vanishing-line estimate outside what a road camera does is more likely wrong than the level prior.
        modules["ground"] = modules.get("ground", "") + (
            f"vanishing-line camera rejected (pitch {pitch:.0f}, roll {roll:.0f} deg beyond "
            f"{cfg.max_camera_pitch_deg}/{cfg.max_camera_roll_deg}); "
        )
    if intrinsics is None:
        modules["camera"] = f"prior: unknown camera, hfov {cfg.default_hfov_deg} deg, principal point at centre"
        intrinsics = Intrinsics.from_fov(w, h, cfg.default_hfov_deg)
    modules["ground"] = modules.get("ground", "") + f"prior: level camera {cfg.camera_height_m} m above the ground"
    return intrinsics, prior_ground_plane(cfg.camera_height_m)


def scene_lighting(
    image, intr: Intrinsics, ground: GroundPlane, cfg: AnalyseConfig, meta: dict, modules: dict
) -> LightingEstimate:
    """Sun (kept apart, for shading and shadows) + SH ambient in the image's linear radiometric units."""
    if not cfg.lighting:
        # Ablation: no estimated lighting. The object is lit by a uniform ambient equal to the image's gray-world
        # irradiance (so it is neither black nor blown out), no sun.
        E = np.asarray(ExposureMatch.from_image(image).irradiance_rgb)
        sh = np.zeros((9, 3))
        sh[0] = E / (np.pi * 0.886227)  # irradiance of a constant SH radiance L00*Y00 is pi * 0.886227 * L00
        modules["lighting"] = skipped("disabled (ablation); uniform gray-world ambient, no sun")
        return LightingEstimate(None, np.zeros(3), sh, 0.0, False, 0.0, "none", ground.normal)
    # one camera height: the ground plane's (measured from depth or poses, else the prior) for the lighting too
    lcfg = cfg.lighting_cfg
    if np.isfinite(ground.camera_height_m) and ground.camera_height_m > 0:
        lcfg = dataclasses.replace(lcfg, camera_height_m=float(ground.camera_height_m))
    # A given environment map (scene fact 'envmap') is the lighting: its sun and ambient, not the image's cues.
    est = estimate_lighting(
        image, intr, None, {**meta, "up_in_world": ground.normal}, envmap=meta.get("envmap"), config=lcfg
    )
    if est.dominant_sun:
        modules["lighting"] = (
            f"sun from {est.source} (confidence {est.confidence:.2f}), sun/sky ratio "
            f"{est.sun_sky_ratio:.2f}, SH ambient"
        )
    else:
        modules["lighting"] = f"no dominant sun ({est.source}): environment (SH) light only"
    return est
