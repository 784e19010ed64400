#!/usr/bin/env python
"""Paired white-band chroma: the same images, placements and analysis, lighting with sky_fill_colour preetham (old)
vs seen (new). Usage: python -m studies.lighting.neutral_whites.white_band N [grey]. Metric: log(B/R) of the white band's mean linear colour minus the
road's (the placeable region's median), and minus the texture white's own log(B/R) (-0.077)."""

import glob
import os
import sys
from dataclasses import replace

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.apply.render import render_object, srgb_to_linear
from aias_augment.apply.stages import apply_plan
from aias_augment.core.config import data_root
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion

n = int(sys.argv[1])
grey = len(sys.argv) > 2
lab = str(data_root() / "tracon/labels/train")
empties = sorted(os.path.basename(p)[:-4] for p in glob.glob(lab + "/*.txt") if os.path.getsize(p) == 0)
pick = [empties[i] for i in np.random.default_rng(5).choice(len(empties), n, replace=False)]
new = replace(load_preset("balanced"), harmonize=False)
old = replace(new, lighting_cfg=replace(new.lighting_cfg, sky_fill_colour="preetham"))
lbr = lambda x: float(np.log(max(x[2], 1e-6) / max(x[0], 1e-6)))
rows = []
for stem in pick:
    img = cv2.cvtColor(cv2.imread(str(data_root() / f"tracon/images/train/{stem}.jpg")), cv2.COLOR_BGR2RGB)
    if grey:
        img = np.repeat(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)[..., None], 3, axis=2)
    s = 640 / max(img.shape[:2])
    img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA) if s < 1 else img
    frame = Frame(img, None)
    an_new = analyse_scene(frame, new)
    an_old = analyse_scene(frame, old)
    if an_new.region is None:
        continue
    road = lbr(np.median(srgb_to_linear(img.astype(np.float32) / 255)[an_new.region.mask], axis=0))
    plan = plan_insertion(an_new, new, np.random.default_rng(1), n_objects=3)
    outs = {"old": apply_plan(frame, an_old, plan, new).image, "new": apply_plan(frame, an_new, plan, new).image}
    wh = np.zeros(img.shape[:2], bool)
    for obj in plan.objects:
        L = render_object(obj.asset, obj.placement.cam_from_object_matrix, an_new.intrinsics, ssaa=1)
        a = L.albedo_linear
        w = (L.alpha > 0.99) & (a.min(-1) > 0.5) & ((a.max(-1) - a.min(-1)) / np.maximum(a.max(-1), 1e-6) < 0.15)
        wh |= cv2.erode(w.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    for k in outs:  # drop clipped pixels
        wh &= outs[k].max(-1) < 250
    if wh.sum() < 10:
        continue
    r = {k: lbr(srgb_to_linear(o[wh].astype(np.float64) / 255).mean(0)) - road for k, o in outs.items()}
    rows.append((r["old"], r["new"]))
    print(
        f"{stem} px {int(wh.sum())} road {road:+.3f} white-road excess old {r['old']:+.3f} new {r['new']:+.3f}",
        flush=True,
    )
d = np.array(rows) + 0.077  # minus the texture white's own log(B/R) (-0.077): 0 = the light's colour is the road's
print(
    f"n={len(d)} images; excess over road, texture tint removed: median old {np.median(d[:, 0]):+.3f} new {np.median(d[:, 1]):+.3f}; "
    f"median |.| old {np.median(np.abs(d[:, 0])):.3f} new {np.median(np.abs(d[:, 1])):.3f}; "
    f"bluer than the road by > 0.1: old {(d[:, 0] > 0.1).sum()} new {(d[:, 1] > 0.1).sum()}"
)
