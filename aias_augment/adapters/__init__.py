"""Thin adapters over the image door: the albumentations transform (:mod:`.transform`), its insertion variants
(:mod:`.variants`) and the input boundary shared with the offline CLI (:mod:`.boundary`)."""
