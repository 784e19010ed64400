"""The colour a white surface facing up in the sun receives, from each KITTI colour frame's lighting estimate, with
the neutral ambient taken back to the sky's colour (``estimate.sky_part_of_neutral``) and without (the ambient in
the photo's grey surfaces' colour, the sun added on top). 1.0 = neutral; the photo's own grey surfaces are the
target, since they receive the same sky plus sun.

    python -m studies.lighting.neutral_whites.sunlit_white_kitti > studies/lighting/neutral_whites/result/sunlit_white_kitti.md
"""

import os
from pathlib import Path

import numpy as np
from PIL import Image

import aias_augment.analyse.lighting.estimate as est_mod
from aias_augment.analyse.lighting.sh import sh_irradiance
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.hdr import srgb_to_linear

K = Intrinsics(707.0912, 707.0912, 601.8873, 183.1104, 1226, 370)  # KITTI 06 colour camera (P2)


def sunlit_white_up(img: np.ndarray, sky_only_ambient: bool) -> tuple[np.ndarray, bool]:
    keep = est_mod.sky_part_of_neutral
    if not sky_only_ambient:
        est_mod.sky_part_of_neutral = lambda sh, up, r: np.asarray(sh, np.float64)
    try:
        e = est_mod.estimate_lighting(img, K)
    finally:
        est_mod.sky_part_of_neutral = keep
    up = e.up_in_cam
    total = sh_irradiance(e.ambient_sh, up[None])[0]
    if e.dominant_sun:
        total = total + e.sun_irradiance_rgb * max(float(e.sun_direction_in_cam @ up), 0.0)
    return total / total[1], e.dominant_sun


def main():
    folder = Path(os.environ.get("AIAS_DATA", "../shared/data")) / "kitti06_color_snippet"
    print(
        "| frame | dominant sun | grey surfaces R/G, B/G (target) | sun on the grey surfaces' colour "
        "| sky's colour + sun |"
    )
    print("|---|---|---|---|---|")
    for p in sorted(folder.glob("*-color.png")):
        img = np.array(Image.open(p).convert("RGB"))
        before, sun = sunlit_white_up(img, False)
        after, _ = sunlit_white_up(img, True)
        g = est_mod.achromatic_light_colour(srgb_to_linear(img.astype(np.float32) / 255.0))
        g = g / g[1]
        print(
            f"| {p.name} | {sun} | {g[0]:.3f}, {g[2]:.3f} | {before[0]:.3f}, {before[2]:.3f} "
            f"| {after[0]:.3f}, {after[2]:.3f} |"
        )


if __name__ == "__main__":
    main()
