"""What the photo's own labelled cones look like: body colour, base colour, white sleeves, measured on their crops.

A cone is a surface of revolution seen upright, so its box's central column runs down the body from the tip to the
base. Along that column (the middle 10 % of the box's width, where the body fills it even near the tip):

- **body**: the median colour of the saturated pixels (HSV S >= 0.45, V >= 0.2) between 15 % and 88 % of the box's
  height (cone bodies are fluorescent plastics, so their pixels are the saturated ones), scaled to a brightest channel
  of 245: the look keeps the body's chromaticity, and the photo's light is the lighting stage's to apply;
- **sleeves**: runs of rows where most pixels are white (S < 0.3 and V at least 0.8 of the body's V), at least 3 % of
  the box's height long, counted and measured (width as a fraction of the body's height);
- **base**: the median of the band at 90-97 % of the box's height over its central 60 %: ``"black"`` when darker than
  0.13 of the body's V (the texture's black is 0.07 of white, its grey 0.22), ``"body"`` when saturated and within 25 deg of the body's hue, else ``"grey"``;
  and its brightness, that V over the body's (``base_value``): the base and the body stand in the same light, so the
  ratio is the cone's own, whatever the photo's exposure, and an inserted cone drawn with it has the base's
  brightness beside its body that the photo's cones have;
- **body brightness** (``body_value``): the body's V itself, the cone's brightness in this photo's light and
  exposure, which an inserted cone drawn like it is scaled to (``cone_brightness: labels``).

A box cut by the frame, shorter than 24 px, or whose column holds too few saturated pixels (a cone seen from above,
a wrong label) gives no look; the caller counts those.

The ground the labelled objects stand on (:func:`labelled_ground`): its colour beside their bases, and every
pixel of that colour, where a row of them is continued.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aias_augment.assets.cone_look import BASE_VALUE_MAX, ConeLook

__all__ = ["LabelledGround", "body_value", "fit_cone_looks", "fit_cone_look", "labelled_ground"]

MIN_BOX_PX = 24  # below this a sleeve is a pixel or two: nothing to measure
MIN_BASE_VALUE = 0.01  # a base read as pure black (V 0) is drawn as the darkest plausible paint, not as no light
BODY_MAX = 245.0  # the brightest channel of a fitted body colour: the family's fluorescent bodies reach 210-255


def _hsv(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) uint8 RGB -> float HSV with H in degrees [0, 360), S and V in [0, 1]."""
    hsv = cv2.cvtColor(np.ascontiguousarray(rgb, np.uint8).reshape(-1, 1, 3), cv2.COLOR_RGB2HSV_FULL)
    h = hsv[..., 0].astype(float) * (360.0 / 256.0)
    return np.stack([h, hsv[..., 1] / 255.0, hsv[..., 2] / 255.0], -1).reshape(rgb.shape)


def _hue_gap(a: float, b: float) -> float:
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


def _body(image_rgb: np.ndarray, box_xyxy):
    """(median RGB, hue, value, the column's HSV) of the body along the box's central column (see the module's
    docstring), or None when too few of its pixels are saturated."""
    x0, y0, x1, y1 = box_xyxy
    h, w = y1 - y0, x1 - x0
    cx0, cx1 = int(round(x0 + 0.45 * w)), max(int(round(x0 + 0.55 * w)), int(round(x0 + 0.45 * w)) + 1)
    r0, r1 = int(round(y0 + 0.15 * h)), int(round(y0 + 0.88 * h))
    col = image_rgb[r0:r1, cx0:cx1]
    if col.size == 0:
        return None
    hsv = _hsv(col)
    sat = (hsv[..., 1] >= 0.45) & (hsv[..., 2] >= 0.2)
    if sat.mean() < 0.25:
        return None
    body_rgb = np.median(col[sat].astype(float), axis=0)
    body_hsv = _hsv(np.clip(body_rgb, 0, 255).astype(np.uint8)[None])[0]
    return body_rgb, float(body_hsv[0]), float(body_hsv[2]), hsv


def body_value(image_rgb: np.ndarray, box_xyxy) -> float | None:
    """The body's brightness in ``image_rgb`` (H, W, 3) uint8 as :func:`fit_cone_look` measures it (HSV value of the
    median saturated colour of the box's central column, 0-1), or None when the column has too few saturated
    pixels; no test of the box against the frame (an object's own render window)."""
    body = _body(image_rgb, tuple(float(v) for v in box_xyxy))
    return None if body is None else body[2]


def fit_cone_look(image_rgb: np.ndarray, box_xyxy) -> ConeLook | None:
    """The :class:`ConeLook` of the cone in ``box_xyxy`` (pixels, x0 y0 x1 y1) of ``image_rgb`` (H, W, 3) uint8, or None
    when the box cannot be measured (see the module's docstring)."""
    H, W = image_rgb.shape[:2]
    x0, y0, x1, y1 = (float(v) for v in box_xyxy)
    if not (x1 > x0 and y1 > y0) or y0 <= 1 or y1 >= H - 2 or x0 < 0 or x1 > W:
        return None
    h, w = y1 - y0, x1 - x0
    if h < MIN_BOX_PX:
        return None
    body = _body(image_rgb, (x0, y0, x1, y1))
    if body is None:
        return None
    body_rgb, body_h, body_v, hsv = body
    white = (hsv[..., 1] < 0.3) & (hsv[..., 2] >= 0.8 * body_v)
    rows = white.mean(axis=1) > 0.5
    min_run = max(2, int(round(0.03 * h)))
    widths, run = [], 0
    for r in np.r_[rows, False]:
        if r:
            run += 1
            continue
        if run >= min_run:
            widths.append(run)
        run = 0
    body_px = 0.9 * h  # the body's height: the box less the base
    bands = min(len(widths), 3)
    width = float(np.clip(np.median(widths) / body_px, 0.02, 0.4)) if widths else 0.0
    b0, b1 = int(round(y0 + 0.90 * h)), max(int(round(y0 + 0.97 * h)), int(round(y0 + 0.90 * h)) + 1)
    band = image_rgb[b0:b1, int(round(x0 + 0.2 * w)) : max(int(round(x1 - 0.2 * w)), int(round(x0 + 0.2 * w)) + 1)]
    if band.size == 0:
        return None
    bh, bs, bv = np.median(_hsv(band).reshape(-1, 3), axis=0)
    if bv < 0.13 * body_v:
        base = "black"
    elif bs >= 0.45 and _hue_gap(float(bh), body_h) <= 25.0:
        base = "body"
    else:
        base = "grey"
    albedo = body_rgb * (BODY_MAX / max(float(body_rgb.max()), 1.0))  # 1.0: a black column never passes `sat`
    base_value = float(np.clip(bv / body_v, MIN_BASE_VALUE, BASE_VALUE_MAX))  # body_v >= 0.2: `sat` pixels only
    return ConeLook(tuple(float(c) for c in albedo), base, bands, width if bands else 0.0, base_value, body_v)


def fit_cone_looks(image_rgb: np.ndarray, boxes_xyxy) -> list[ConeLook]:
    """The looks of every measurable cone among ``boxes_xyxy`` (N, 4): see :func:`fit_cone_look`."""
    out = []
    for b in np.asarray(boxes_xyxy, float).reshape(-1, 4):
        look = fit_cone_look(image_rgb, b)
        if look is not None:
            out.append(look)
    return out


#: Ground beside a labelled object's base: rows of the box's lowest tenth, out to this share of its width either side.
GROUND_STRIP_WIDTH = 0.35
#: Pixels of ground beside the bases needed before their colour says which pixels are that ground.
GROUND_MIN_SAMPLES = 60
#: A pixel is the row's ground within this many robust spreads of its median colour (CIELAB), each spread at least
#: the floor (L, a, b): a uniform asphalt's spread is a few levels, and its shading along a row more.
GROUND_SPREADS = 3.0
GROUND_SPREAD_FLOOR = (8.0, 4.0, 4.0)


@dataclass(frozen=True)
class LabelledGround:
    """The ground the labelled objects of an image stand on, by its look (:func:`labelled_ground`): the image, the
    pixels inside a labelled box (never ground) and the CIELAB range of the ground beside their bases. A pixel's
    colour is converted when it is asked about (:meth:`at`), so a caller that needs a few thousand pixels (a row's
    sites) pays for those alone."""

    image: np.ndarray  # (H, W, 3) uint8 RGB
    inside: np.ndarray  # (H, W) bool: in a labelled box
    lo: np.ndarray  # (3,) the range's CIELAB (8-bit) bounds, inclusive
    hi: np.ndarray

    def at(self, flat: np.ndarray) -> np.ndarray:
        """Whether each pixel of ``flat`` (indices into the image's pixels, row-major) is that ground."""
        flat = np.asarray(flat, np.int64)
        if not len(flat):
            return np.zeros(0, bool)
        px = self.image.reshape(-1, 3)[flat].reshape(-1, 1, 3)
        lab = cv2.cvtColor(px, cv2.COLOR_RGB2LAB).reshape(-1, 3)
        return np.all((lab >= self.lo) & (lab <= self.hi), axis=1) & ~self.inside.reshape(-1)[flat]

    def mask(self) -> np.ndarray:
        """(H, W) bool: :meth:`at` over every pixel."""
        h, w = self.inside.shape
        return self.at(np.arange(h * w)).reshape(h, w)


def labelled_ground(image_rgb: np.ndarray, boxes_xyxy) -> LabelledGround | None:
    """The ground the labelled objects ``boxes_xyxy`` (N, 4) stand on, or None when too little of it is seen. The
    ground is sampled beside each base (the box's lowest tenth of rows, out to :data:`GROUND_STRIP_WIDTH` of its
    width either side, every labelled box left out); a pixel is that ground when each CIELAB channel is within
    :data:`GROUND_SPREADS` robust spreads of the samples' median. Inside a labelled box is never ground. What the
    image's own road region (``analyse/region.py``, seeded at the frame's bottom and eroded round every edge) leaves
    out between and beside a row of labelled objects, this finds."""
    img = np.ascontiguousarray(image_rgb, np.uint8)
    h, w = img.shape[:2]
    boxes = np.asarray(boxes_xyxy, float).reshape(-1, 4)
    if not len(boxes):
        return None
    inside = np.zeros((h, w), bool)
    for x0, y0, x1, y1 in boxes:
        rows = slice(max(0, int(np.floor(y0))), max(0, int(np.ceil(y1))))
        inside[rows, max(0, int(np.floor(x0))) : max(0, int(np.ceil(x1)))] = True
    strip = np.zeros((h, w), bool)
    for x0, y0, x1, y1 in boxes:
        bw, bh = x1 - x0, y1 - y0
        r0, r1 = int(np.clip(y1 - 0.1 * bh, 0, h)), int(np.clip(np.ceil(y1), 0, h))
        for c0, c1 in ((x0 - GROUND_STRIP_WIDTH * bw, x0), (x1, x1 + GROUND_STRIP_WIDTH * bw)):
            strip[r0:r1, int(np.clip(c0, 0, w)) : int(np.clip(np.ceil(c1), 0, w))] = True
    strip &= ~inside
    if strip.sum() < GROUND_MIN_SAMPLES:
        return None
    samples = cv2.cvtColor(img[strip].reshape(-1, 1, 3), cv2.COLOR_RGB2LAB).reshape(-1, 3).astype(np.float64)
    med = np.median(samples, axis=0)
    tol = GROUND_SPREADS * np.maximum(1.4826 * np.median(np.abs(samples - med), axis=0), GROUND_SPREAD_FLOOR)
    # |x - med| <= tol on 8-bit channels is ceil(med - tol) <= x <= floor(med + tol)
    lo, hi = np.clip(np.ceil(med - tol), 0, 255), np.clip(np.floor(med + tol), 0, 255)
    return LabelledGround(img, inside, lo.astype(np.uint8), hi.astype(np.uint8))
