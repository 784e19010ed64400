import numpy as np
import pytest
from PIL import Image

from aias_augment.bank.procedural import GENERATORS, ProceduralSpec, generate


@pytest.mark.parametrize("gen", sorted(GENERATORS))
def test_generators_are_labelled_sized_and_deterministic(gen):
    spec = ProceduralSpec(gen, "debris", (0.05, 0.3))
    tex = Image.fromarray(np.random.default_rng(0).integers(0, 255, (32, 32, 3)).astype(np.uint8))
    a = generate(spec, np.random.default_rng(7), tex)
    b = generate(spec, np.random.default_rng(7), tex)
    c = generate(spec, np.random.default_rng(8), tex)
    assert a.procedural and a.source == f"procedural:{gen}" and a.meta["textured"]
    assert a.height_m == pytest.approx(a.meta["height_m"], rel=1e-6)
    assert 0.05 <= a.height_m <= 0.3
    assert abs(a.bounds_m[0, 2]) < 1e-9
    np.testing.assert_array_equal(a.meshes[0].vertices, b.meshes[0].vertices)
    assert a.meshes[0].vertices.shape != c.meshes[0].vertices.shape or not np.allclose(a.meshes[0].vertices,
                                                                                        c.meshes[0].vertices)
    m = a.meshes[0]
    assert np.all(np.isfinite(m.vertices)) and m.visual.uv is not None and len(m.visual.uv) == len(m.vertices)
    assert np.all(m.area_faces > 0)


def test_untextured_fallback_and_unknown_generator():
    a = generate(ProceduralSpec("stone", "rock", (0.1, 0.2)), np.random.default_rng(0), None)
    assert a.meshes[0].visual.uv is None and not a.meta["textured"]
    with pytest.raises(ValueError, match="unknown generator"):
        generate(ProceduralSpec("blob", "rock", (0.1, 0.2)), np.random.default_rng(0))
