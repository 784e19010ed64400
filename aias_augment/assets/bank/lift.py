"""Assets from the user's own labelled instances: cut each labelled object out of its photo and lift it into 3D.

A detector learns a class from how the class looks in the user's data; a mesh from elsewhere is another object
(TraCon's cones against the shared cone mesh: shape alone separates them at AUC 0.98). So the instances the user
already labelled become insertable assets:

1. :func:`cut_out`: GrabCut initialised by the labelled box (no downloaded weights), the largest connected
   component kept and its holes filled, the edge softened by a guided filter. An instance is rejected with a named,
   counted reason when it is truncated by the frame, overlapped by another labelled box (probably occluded), too
   small, or badly segmented (its mask does not fill the labelled box).
2. :func:`lift_revolution` (rotationally symmetric classes: cones, drums, bollards, posts, barrels): the silhouette
   read as a radius profile r(z) (a side view seen from afar: half the mask's width per row), revolved into a closed
   surface; its texture is the photo itself, each surface point taking the pixel its visible twin projects to (the
   unseen back mirrors the front). :func:`lift_card` (other classes): a vertical textured card with the cutout's
   alpha in its texture, standing on the ground.
3. Metric height from the class's size range (the placement rescales the asset to the size it draws anyway).

Every asset records its source (image, box) in ``meta``; :func:`lift_instances` writes GLB files and a
``bank.json`` that :class:`LiftedAssets` reads back as an asset source for the pipeline (``bank=``) or
``InsertObjects(assets=...)``.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from aias_augment.assets.asset import CATEGORY_HEIGHT_RANGE_M
from aias_augment.core.hdr import linear_to_srgb, srgb_to_linear

log = logging.getLogger(__name__)

#: Classes whose instances are surfaces of revolution about a vertical axis.
REVOLUTION_CATEGORIES = frozenset(
    {"traffic_cone", "cone", "barrel", "drum", "bollard", "post", "traffic_drum", "delineator"}
)


@dataclass(frozen=True)
class LiftConfig:
    min_box_px: int = 24  # box height and width below this: "too small"
    border_px: int = 2  # a box within this of the frame's edge: "truncated"
    max_overlap: float = 0.10  # fraction of the box covered by another labelled box: "occluded"
    min_fill: float = 0.30  # mask area / box area below: "badly segmented"
    min_box_iou: float = 0.70  # IoU of the mask's own box with the labelled box below: "badly segmented"
    grabcut_iters: int = 5
    context: float = 0.5  # context around the box given to GrabCut, as a fraction of the box size
    segments: int = 48  # around the axis
    max_rings: int = 64  # along the axis
    texture_height: int = 256
    edge_inset: float = 0.94  # texture samples at most this far out of the axis (the silhouette's own
    # pixels are mixed with the background)
    # The photo's pixels are its light times the albedo; the pipeline lights the texture again. The texture is scaled
    # (in linear light, one factor) so that the object's 95th-percentile luminance is this albedo: a photo's brightest
    # surface (a cone's white band) taken as a bright paint, whatever the photo's exposure. None: the pixels as they are.
    albedo_p95: float | None = 0.8
    max_albedo_gain: float = 3.0  # the factor is kept within [1 / max, max]
    min_profile_iou: float = 0.85  # the silhouette against its straight-axis surface of revolution below this:
    # "not a surface of revolution" (a knocked-over or cut cone)

    def __post_init__(self):
        if self.min_box_px < 4 or self.segments < 8 or self.max_rings < 2 or self.texture_height < 8:
            raise ValueError(f"LiftConfig out of range: {self}")
        if self.albedo_p95 is not None and not 0 < self.albedo_p95 <= 1 or self.max_albedo_gain < 1:
            raise ValueError(f"LiftConfig albedo normalisation out of range: {self}")
        if not (0 < self.min_fill < 1 and 0 < self.min_box_iou <= 1 and 0 < self.edge_inset <= 1):
            raise ValueError(f"LiftConfig fractions out of range: {self}")


@dataclass(frozen=True, eq=False)
class Cutout:
    """One labelled instance cut out of its photo: the crop around its box and the object's mask in it."""

    source_image: str
    box_xyxy: tuple[float, float, float, float]  # the label, in the photo's pixels
    crop_xy: tuple[int, int]  # the crop's top-left corner in the photo
    rgb: np.ndarray  # (h, w, 3) uint8 crop
    mask: np.ndarray  # (h, w) bool: the object
    alpha: np.ndarray  # (h, w) float32 in [0, 1]: the mask with a soft edge
    meta: dict = field(default_factory=dict)

    @property
    def mask_box(self) -> tuple[int, int, int, int]:
        ys, xs = np.nonzero(self.mask)
        return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1


def _box_iou(a, b) -> float:
    iw = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    ih = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = iw * ih
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def _covered_fraction(box, others) -> float:
    """Fraction of ``box``'s area covered by the union of ``others`` (rasterised at 1 px)."""
    x0, y0, x1, y1 = (int(np.floor(box[0])), int(np.floor(box[1])), int(np.ceil(box[2])), int(np.ceil(box[3])))
    if not len(others) or x1 <= x0 or y1 <= y0:
        return 0.0
    cover = np.zeros((y1 - y0, x1 - x0), bool)
    for o in others:
        ox0, oy0 = max(int(np.floor(o[0])), x0) - x0, max(int(np.floor(o[1])), y0) - y0
        ox1, oy1 = min(int(np.ceil(o[2])), x1) - x0, min(int(np.ceil(o[3])), y1) - y0
        if ox1 > ox0 and oy1 > oy0:
            cover[oy0:oy1, ox0:ox1] = True
    return float(cover.mean())


def cut_out(
    image: np.ndarray, box_xyxy, other_boxes_xyxy=(), cfg: LiftConfig = LiftConfig(), source: str = ""
) -> tuple[Cutout | None, str]:
    """(cutout, "ok") or (None, reason) for the instance labelled ``box_xyxy`` in ``image`` (H, W, 3 uint8 RGB).

    Deterministic: GrabCut's Gaussian mixtures are initialised by OpenCV's k-means under a fixed RNG state."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image must be (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
    h, w = img.shape[:2]
    b = np.asarray(box_xyxy, np.float64).reshape(4)
    if not np.all(np.isfinite(b)) or b[2] <= b[0] or b[3] <= b[1]:
        return None, "invalid box"
    bw, bh = b[2] - b[0], b[3] - b[1]
    if bw < cfg.min_box_px or bh < cfg.min_box_px:
        return None, "too small"
    if b[0] < cfg.border_px or b[1] < cfg.border_px or b[2] > w - cfg.border_px or b[3] > h - cfg.border_px:
        return None, "truncated by the frame"
    others = [np.asarray(o, np.float64) for o in other_boxes_xyxy]
    if _covered_fraction(b, others) > cfg.max_overlap:
        return None, "occluded (overlaps another labelled box)"
    mx, my = cfg.context * bw, cfg.context * bh
    cx0, cy0 = int(max(0, np.floor(b[0] - mx))), int(max(0, np.floor(b[1] - my)))
    cx1, cy1 = int(min(w, np.ceil(b[2] + mx))), int(min(h, np.ceil(b[3] + my)))
    crop = np.ascontiguousarray(img[cy0:cy1, cx0:cx1])
    rect = (int(round(b[0])) - cx0, int(round(b[1])) - cy0, max(1, int(round(bw))), max(1, int(round(bh))))
    gc = np.zeros(crop.shape[:2], np.uint8)
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)
    try:
        cv2.grabCut(cv2.cvtColor(crop, cv2.COLOR_RGB2BGR), gc, rect, bgd, fgd, cfg.grabcut_iters, cv2.GC_INIT_WITH_RECT)
    except cv2.error as exc:
        return None, f"badly segmented (GrabCut failed: {str(exc).splitlines()[0][:80]})"
    fg = ((gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n <= 1:
        return None, "badly segmented (empty mask)"
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    mask = (lab == largest).astype(np.uint8)
    # Holes (a white band GrabCut gave to the road) filled: the outer contour's interior.
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(mask)
    cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
    mask = filled.astype(bool)
    ys, xs = np.nonzero(mask)
    mbox = (xs.min() + cx0, ys.min() + cy0, xs.max() + 1 + cx0, ys.max() + 1 + cy0)
    fill = mask.sum() / max(bw * bh, 1.0)
    iou = _box_iou(mbox, b)
    if fill < cfg.min_fill or iou < cfg.min_box_iou:
        return None, "badly segmented (mask does not fill the box)"
    alpha = _soft_alpha(crop, mask)
    # The labeller's convention: how far the label box lies outside the object's mask on each side (left, top,
    # right, bottom; fractions of the box's width or height; negative where the label cuts into the object).
    margins = [(mbox[0] - b[0]) / bw, (mbox[1] - b[1]) / bh, (b[2] - mbox[2]) / bw, (b[3] - mbox[3]) / bh]
    return Cutout(
        source,
        tuple(map(float, b)),
        (cx0, cy0),
        crop,
        mask,
        alpha,
        {"fill": float(fill), "mask_box_iou": float(iou), "label_margins_frac": [round(float(m), 4) for m in margins]},
    ), "ok"


def _soft_alpha(crop: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The binary mask with its edge refined by a guided filter on the photo (radius 2 px), zero outside a 3 px
    band of the mask."""
    m = mask.astype(np.float32)
    try:
        a = cv2.ximgproc.guidedFilter(crop, m, 2, 1e-3)
    except (AttributeError, cv2.error):
        a = cv2.GaussianBlur(m, (0, 0), 0.8)
    band = cv2.dilate(mask.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    a = np.where(band, np.clip(a, 0.0, 1.0), 0.0).astype(np.float32)
    a[cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)] = 1.0
    return a


def silhouette_profile(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per mask row from top to bottom: (row index, centre x, radius) in crop pixels. The radius is half the row's
    extent (a pixel's far edge counted: a row covering columns 3..6 has half-width 2); rows the mask skips are
    interpolated; the profile is smoothed by a 5-row median so single noisy rows do not make ridges."""
    ys = np.nonzero(mask.any(axis=1))[0]
    rows = np.arange(ys.min(), ys.max() + 1)
    left = np.full(len(rows), np.nan)
    right = np.full(len(rows), np.nan)
    for k, y in enumerate(rows):
        xs = np.nonzero(mask[y])[0]
        if len(xs):
            left[k], right[k] = xs.min(), xs.max() + 1.0
    ok = np.isfinite(left)
    idx = np.arange(len(rows))
    left = np.interp(idx, idx[ok], left[ok])
    right = np.interp(idx, idx[ok], right[ok])
    radius = 0.5 * (right - left)
    centre = 0.5 * (right + left)
    if len(rows) >= 5:
        pad = np.pad(radius, 2, mode="edge")
        radius = np.median(np.lib.stride_tricks.sliding_window_view(pad, 5), axis=1)
    return rows, centre, radius


def lift_revolution(cut: Cutout, height_m: float, cfg: LiftConfig = LiftConfig()):
    """A closed, textured surface of revolution (trimesh, metres, z up, base on z = 0, axis on x = y = 0) from the
    cutout's silhouette, ``height_m`` tall. Rings follow the silhouette's rows (at most ``cfg.max_rings``, the
    silhouette's top and bottom rows always included), ``cfg.segments`` around; flat caps close it."""
    import trimesh
    from PIL import Image

    if not (np.isfinite(height_m) and height_m > 0):
        raise ValueError(f"height_m must be positive and finite, got {height_m}")
    rows, centre, radius = silhouette_profile(cut.mask)
    n_px = float(len(rows))  # the silhouette's height in pixels (a row is a pixel tall)
    s = height_m / n_px  # metres per pixel
    n_r = int(min(cfg.max_rings, len(rows) + 1))
    # Ring k at the height of pixel edge t_k (0 = the top edge of the top row, n_px = the bottom edge of the bottom
    # row); its radius is the profile's at that edge (the rows' values interpolated, the end rows held).
    t = np.linspace(0.0, n_px, n_r)
    r_edge = np.interp(t - 0.5, np.arange(len(rows), dtype=float), radius)
    z = (n_px - t) * s
    r = np.maximum(r_edge, 0.0) * s
    seg = cfg.segments
    phi = 2 * np.pi * np.arange(seg + 1) / seg  # seg + 1: the texture seam has its own column
    verts = np.stack(
        [r[:, None] * np.cos(phi)[None], r[:, None] * np.sin(phi)[None], np.broadcast_to(z[:, None], (n_r, seg + 1))],
        -1,
    ).reshape(-1, 3)
    uv = np.stack(np.meshgrid(np.arange(seg + 1) / seg, 1.0 - t / n_px), -1).reshape(-1, 2)
    faces = []
    for k in range(n_r - 1):
        a = k * (seg + 1) + np.arange(seg)
        b = a + (seg + 1)
        faces.append(np.stack([a, b, a + 1], 1))  # outward normals (counter-clockwise seen from outside)
        faces.append(np.stack([a + 1, b, b + 1], 1))
    faces = np.concatenate(faces)
    # Caps: a centre vertex at the top and the bottom, fanned to the first and last ring.
    top_c, bot_c = len(verts), len(verts) + 1
    verts = np.vstack([verts, [0, 0, z[0]], [0, 0, z[-1]]])
    uv = np.vstack([uv, [0.5, 1.0], [0.5, 0.0]])
    ring0 = np.arange(seg)
    ringn = (n_r - 1) * (seg + 1) + np.arange(seg)
    faces = np.vstack(
        [
            faces,
            np.stack([np.full(seg, top_c), ring0 + 1, ring0], 1),
            np.stack([np.full(seg, bot_c), ringn, ringn + 1], 1),
        ]
    )
    # Texture: texel (row v, column u) takes the photo's pixel where the surface point at height v and angle
    # phi(u) -- or its mirror twin on the visible half -- projects: x = centre + r cos(phi) (a side view from -y).
    th = int(cfg.texture_height)
    tw = 2 * th
    tv = (np.arange(th) + 0.5) / th * n_px - 0.5  # texture row -> silhouette row (fractional)
    cv_ = np.interp(tv, np.arange(len(rows), dtype=float), centre)
    rv = np.interp(tv, np.arange(len(rows), dtype=float), radius)
    cphi = np.cos(2 * np.pi * (np.arange(tw) + 0.5) / tw)
    map_x = (cv_[:, None] + cfg.edge_inset * rv[:, None] * cphi[None] - 0.5).astype(np.float32)
    map_y = np.broadcast_to((rows[0] + tv)[:, None], (th, tw)).astype(np.float32)
    tex = cv2.remap(cut.rgb, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    tex = normalise_albedo(tex, cut.rgb[cut.mask], cfg)
    visual = trimesh.visual.TextureVisuals(uv=uv, material=_material(Image.fromarray(tex)))
    mesh = trimesh.Trimesh(verts, faces, visual=visual, process=False)
    mesh.metadata["profile_m"] = {"z": z.tolist(), "r": r.tolist()}
    return mesh


def _material(image):
    """A matte material whose base colour is the texture itself (trimesh's default material would scale it by its
    grey diffuse factor, 0.4)."""
    import trimesh

    return trimesh.visual.material.PBRMaterial(
        baseColorTexture=image,
        baseColorFactor=[255, 255, 255, 255],
        metallicFactor=0.0,
        roughnessFactor=1.0,
        doubleSided=True,
    )


def normalise_albedo(tex: np.ndarray, object_pixels: np.ndarray, cfg: LiftConfig) -> np.ndarray:
    """``tex`` (uint8 sRGB) times one factor in linear light that brings the object's 95th-percentile luminance to
    ``cfg.albedo_p95`` (within ``cfg.max_albedo_gain``); unchanged when that is None."""
    if cfg.albedo_p95 is None or not len(object_pixels):
        return tex
    lum = srgb_to_linear(object_pixels.astype(np.float32) / 255.0) @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    p95 = float(np.percentile(lum, 95))
    gain = float(np.clip(cfg.albedo_p95 / max(p95, 1e-6), 1.0 / cfg.max_albedo_gain, cfg.max_albedo_gain))
    lin = np.clip(srgb_to_linear(tex.astype(np.float32) / 255.0) * gain, 0.0, 1.0)
    return np.clip(np.round(linear_to_srgb(lin) * 255.0), 0, 255).astype(np.uint8)


def profile_iou(mask: np.ndarray) -> float:
    """IoU of the silhouette with the surface of revolution lifted from it seen from its source view (a straight
    vertical axis at the mean centre column, each row's half-width its radius): how well the instance is a
    surface of revolution standing upright."""
    rows, centre, radius = silhouette_profile(mask)
    c = float(np.mean(centre))
    xs = np.arange(mask.shape[1]) + 0.5
    model = np.zeros_like(mask, bool)
    model[rows] = np.abs(xs[None] - c) <= radius[:, None]
    return float((model & mask).sum() / max((model | mask).sum(), 1))


def lift_card(cut: Cutout, height_m: float):
    """A vertical card (the x-z plane, facing -y), ``height_m`` tall, textured with the cutout (alpha in the
    texture), standing on z = 0: for classes that are not surfaces of revolution."""
    import trimesh
    from PIL import Image

    x0, y0, x1, y1 = cut.mask_box
    s = height_m / (y1 - y0)
    w = (x1 - x0) * s
    verts = np.array([[-w / 2, 0, 0], [w / 2, 0, 0], [w / 2, 0, height_m], [-w / 2, 0, height_m]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]])  # both sides
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    rgba = np.dstack([cut.rgb[y0:y1, x0:x1], np.round(cut.alpha[y0:y1, x0:x1] * 255).astype(np.uint8)])
    visual = trimesh.visual.TextureVisuals(uv=uv, material=_material(Image.fromarray(rgba, "RGBA")))
    return trimesh.Trimesh(verts, faces, visual=visual, process=False)


def class_height_m(category: str) -> float:
    """The middle of the category's real height range (the placement rescales to the size it draws)."""
    lo, hi = CATEGORY_HEIGHT_RANGE_M.get(category, (1.0, 1.0))
    return 0.5 * (lo + hi)


@dataclass
class LiftReport:
    lifted: int = 0
    rejected: Counter = field(default_factory=Counter)
    assets: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"lifted": self.lifted, "rejected": dict(self.rejected), "assets": self.assets}


def _cut_instances(items, cfg: LiftConfig):
    """(path, index in its image, box, cutout or None, reason) for every labelled box of ``items`` (``(image_path,
    image_rgb, boxes_xyxy[, other_boxes_xyxy])``); the other boxes of the image, of its class or not, can occlude
    it."""
    for path, image, boxes, *rest in items:
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        other_class = [np.asarray(b, np.float64) for b in (rest[0] if rest else ())]
        for k, box in enumerate(boxes):
            others = [boxes[j] for j in range(len(boxes)) if j != k] + other_class
            cut, reason = cut_out(image, box, others, cfg, source=str(path))
            yield path, k, box, cut, reason


def lift_instances(
    items,
    category: str,
    out_dir: str | Path | None = None,
    cfg: LiftConfig = LiftConfig(),
    height_m: float | None = None,
    mode: str | None = None,
):
    """Lift every labelled instance of ``items`` (an iterable of ``(image_path, image_rgb, boxes_xyxy[,
        other_boxes_xyxy])``: every box of the class in the image, and optionally the boxes of other classes, which can
        occlude it too) into assets of ``category``. Returns ``(assets, report)``; with ``out_dir`` each
        asset is also appended to that bank folder (:func:`aias_augment.assets.bank.db.append_entry`: ``NNNN.glb`` and
    its ``bank.json`` entry with category, source image and box, mode; the entries already there are kept).

        ``mode``: "revolution" or "card" (default: revolution for :data:`REVOLUTION_CATEGORIES`)."""
    from aias_augment.assets.asset import Asset, normalise_meshes
    from aias_augment.assets.bank.db import append_entry, check_folder, set_rejected
    from aias_augment.assets.bank.folder import glb_bytes

    mode = mode or ("revolution" if category in REVOLUTION_CATEGORIES else "card")
    if mode not in ("revolution", "card"):
        raise ValueError(f"mode must be 'revolution' or 'card', got {mode!r}")
    h_m = class_height_m(category) if height_m is None else float(height_m)
    out = None if out_dir is None else check_folder(out_dir)
    header = {"category": category, "config": asdict(cfg)}
    report, assets = LiftReport(), []
    for path, k, box, cut, reason in _cut_instances(items, cfg):
        if cut is not None and mode == "revolution" and profile_iou(cut.mask) < cfg.min_profile_iou:
            cut, reason = None, "not a surface of revolution (tilted or cut)"
        if cut is None:
            report.rejected[reason] += 1
            log.info("%s box %d: not lifted: %s", path, k, reason)
            continue
        mesh = lift_revolution(cut, h_m, cfg) if mode == "revolution" else lift_card(cut, h_m)
        idx = len(assets)
        meta = {"source_image": str(path), "source_box_xyxy": list(map(float, box)), "lift_mode": mode, **cut.meta}
        name = f"lifted_{category}_{idx:04d}"
        src = str(path)
        if out is not None:
            entry, _ = append_entry(out, glb_bytes([mesh]), {"category": category, "height_m": h_m, **meta}, header)
            src = str(out / entry["file"])
            report.assets.append(entry)
        assets.append(Asset(name, category, normalise_meshes([mesh]), src, "the user's own labelled data", False, meta))
        report.lifted += 1
    if out is not None:
        set_rejected(out, dict(report.rejected), header)
    return assets, report


BOX_SIDES = ("left", "top", "right", "bottom")


def measure_box_convention(items, cfg: LiftConfig = LiftConfig()) -> tuple[tuple[float, float, float, float], dict]:
    """How the labellers of ``items`` (as :func:`lift_instances` takes them) draw a box around an object: per side,
    the median over the instances :func:`cut_out` accepts of how far the label lies outside the object's mask, as a
    fraction of the label's width or height (what ``InsertionConfig.box_convention`` takes). Returns ``(margins,
    report)``: the report counts the instances measured and rejected (by reason) and gives each side's percentiles.

    GrabCut starts from the label box (outside it is background), so a label that cuts into the object measures 0
    on that side, never less: the margins bound a label's looseness from above where it is loose, and read 0 where
    it is tight or cuts in. Raises ValueError when no instance can be measured."""
    margins, rejected = [], Counter()
    for _, _, _, cut, reason in _cut_instances(items, cfg):
        if cut is None:
            rejected[reason] += 1
        else:
            margins.append(cut.meta["label_margins_frac"])
    if not margins:
        raise ValueError(f"no labelled instance could be measured (rejected: {dict(rejected)})")
    m = np.clip(np.asarray(margins, np.float64), 0.0, None)
    median = tuple(round(float(v), 4) for v in np.median(m, axis=0))
    report = {
        "instances_measured": len(m),
        "rejected": dict(rejected),
        "margin_frac_percentiles": {
            side: {str(q): round(float(np.percentile(m[:, i], q)), 4) for q in (10, 25, 50, 75, 90)}
            for i, side in enumerate(BOX_SIDES)
        },
    }
    return median, report


def bank_paths(folder: str | Path) -> dict[str, list[str]]:
    """``{category: [GLB paths]}`` of a bank folder written by :func:`lift_instances`: what
    ``InsertObjects(assets=...)`` and the offline CLI's ``--assets`` take."""
    from aias_augment.assets.bank.db import read_index

    folder = Path(folder)
    if not (folder / "bank.json").is_file():
        raise FileNotFoundError(f"{folder}: no bank.json (write one with `aias-assets from-labels`)")
    out: dict[str, list[str]] = {}
    for e in read_index(folder)["report"]["assets"]:
        out.setdefault(e["category"], []).append(str(folder / e["file"]))
    if not out:
        raise ValueError(f"{folder}: the bank holds no lifted asset")
    return out


class LiftedAssets:
    """An asset source (``bank=`` of the pipeline) drawing uniformly from lifted assets per category: in memory
    (``LiftedAssets({"traffic_cone": assets})``) or from a folder written by :func:`lift_instances`
    (:meth:`from_dir`, loaded lazily, so it pickles small into workers)."""

    def __init__(self, assets: dict[str, list], folder: str | None = None):
        if not assets and folder is None:
            raise ValueError("LiftedAssets needs at least one asset")
        for c, a in assets.items():
            if not a:
                raise ValueError(f"LiftedAssets: category {c!r} has no assets")
        self._assets = dict(assets)
        self.folder = folder

    @classmethod
    def from_dir(cls, folder: str | Path) -> "LiftedAssets":
        from aias_augment.assets.bank.db import read_index

        folder = Path(folder)
        if not (folder / "bank.json").is_file():
            raise FileNotFoundError(f"{folder}: no bank.json (write one with `aias-assets from-labels`)")
        bank = read_index(folder)
        if not bank["report"]["assets"]:
            raise ValueError(f"{folder}: the bank holds no lifted asset ({bank['report']['rejected']})")
        return cls({}, str(folder))

    def _load(self) -> None:
        from aias_augment.assets.asset import bank_entry_meta, load_asset
        from aias_augment.assets.bank.db import read_index

        if self._assets or self.folder is None:
            return
        bank = read_index(self.folder)
        out: dict[str, list] = {}
        for e in bank["report"]["assets"]:
            a = load_asset(Path(self.folder) / e["file"], category=e["category"], scale=1.0)
            a.meta.update(bank_entry_meta(Path(self.folder) / e["file"]))
            out.setdefault(e["category"], []).append(a)
        self._assets = out

    def categories(self) -> list[str]:
        self._load()
        return sorted(self._assets)

    def sample(self, category: str, rng: np.random.Generator):
        self._load()
        if category not in self._assets:
            raise KeyError(f"no lifted assets of {category!r}; have {sorted(self._assets)}")
        a = self._assets[category]
        return a[int(rng.integers(len(a)))]

    def __getstate__(self):
        return {"_assets": {} if self.folder is not None else self._assets, "folder": self.folder}
