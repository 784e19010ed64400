"""What a photo's own cones look like, as the procedural cone generator draws it (:class:`ConeLook`). Kept apart from
the generator so that measuring and planning looks never imports the mesh libraries."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ConeLook", "BASE_VALUE_MAX"]

BASE_VALUE_MAX = 2.0  # a base brighter than twice its body is a measurement of something else


@dataclass(frozen=True)
class ConeLook:
    """What a photo's own cones look like, to draw inserted cones like them: the body colour (sRGB 0-255), the base's
    colour class (``"black"``, ``"grey"`` or ``"body"``), the number of white sleeves (0-3), each sleeve's width as a
    fraction of the body's height and, when measured, the base's brightness as a fraction of the body's
    (``base_value``: HSV value over HSV value, both lit by the same light, so the photo's exposure cancels). Measured
    on labelled crops by :func:`aias_augment.analyse.instances.fit_cone_looks`; without ``base_value`` the base class
    gives the base's colour. ``body_value``, when measured: the body's HSV value in its photo (0-1), the brightness
    an inserted cone drawn like it is given there (not a property of the cone: of the cone in that light).
    """

    colour_rgb: tuple[float, float, float]
    base_colour: str
    bands: int
    band_width_frac: float
    base_value: float | None = None
    body_value: float | None = None

    def __post_init__(self) -> None:
        if self.base_colour not in ("black", "grey", "body"):
            raise ValueError(f"ConeLook.base_colour must be black, grey or body, got {self.base_colour!r}")
        if not 0 <= int(self.bands) <= 3:
            raise ValueError(f"ConeLook.bands must be 0-3, got {self.bands}")
        if not (len(self.colour_rgb) == 3 and all(0 <= float(c) <= 255 for c in self.colour_rgb)):
            raise ValueError(f"ConeLook.colour_rgb must be 3 values in 0-255, got {self.colour_rgb}")
        if self.bands and not 0.02 <= float(self.band_width_frac) <= 0.4:
            raise ValueError(f"ConeLook.band_width_frac must be in 0.02-0.4 with sleeves, got {self.band_width_frac}")
        if self.body_value is not None and not 0.0 < float(self.body_value) <= 1.0:
            raise ValueError(f"ConeLook.body_value must be in (0, 1], got {self.body_value}")
        if self.base_value is not None and not 0.0 < float(self.base_value) <= BASE_VALUE_MAX:
            raise ValueError(f"ConeLook.base_value must be in (0, {BASE_VALUE_MAX}], got {self.base_value}")

    def to_dict(self) -> dict:
        d = {
            "colour_rgb": [float(c) for c in self.colour_rgb],
            "base_colour": self.base_colour,
            "bands": int(self.bands),
            "band_width_frac": float(self.band_width_frac),
        }
        for k in ("base_value", "body_value"):
            if getattr(self, k) is not None:
                d[k] = float(getattr(self, k))
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ConeLook:
        return cls(
            tuple(float(c) for c in d["colour_rgb"]),
            str(d["base_colour"]),
            int(d["bands"]),
            float(d["band_width_frac"]),
            None if d.get("base_value") is None else float(d["base_value"]),
            None if d.get("body_value") is None else float(d["body_value"]),
        )
