"""The README's two training-loop blocks run as written, in a folder holding ``street.jpg``."""

from pathlib import Path

import numpy as np
from PIL import Image

from tests.aias_augment.pipeline.test_image import road_frame


def readme_python_block(marker: str) -> str:
    """The fenced python block that follows ``<!-- readme-test: marker -->`` in README.md."""
    text = (Path(__file__).resolve().parents[3] / "README.md").read_text()
    after = text.split(f"<!-- readme-test: {marker} -->", 1)[1]
    return after.split("```python\n", 1)[1].split("```", 1)[0]


def _run(marker: str, tmp_path, monkeypatch) -> dict:
    Image.fromarray(road_frame()).save(tmp_path / "street.jpg", quality=95)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(readme_python_block(marker), f"README.md:{marker}", "exec"), namespace)
    return namespace


def test_readme_transform_block_runs_as_written(tmp_path, monkeypatch):
    ns = _run("transform-targets", tmp_path, monkeypatch)
    out = ns["out"]
    assert out["labels"].count(1) >= 1 and out["labels"][0] == 0
    for (x0, y0, x1, y1), m in zip(out["bboxes"][1:], out["masks"][1:]):  # the new objects: box = mask's box
        ys, xs = np.nonzero(m)
        assert np.allclose([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], [x0, y0, x1, y1], atol=1.0)
    assert set(np.unique(out["mask"])) <= {0, 1, 2} and (out["mask"] == 1).any()


def test_readme_torchvision_block_runs_as_written(tmp_path, monkeypatch):
    ns = _run("torchvision-v2", tmp_path, monkeypatch)
    image, target = ns["image"], ns["target"]
    assert image.shape[0] == 3 and image.dtype.is_floating_point is False
    assert len(target["boxes"]) == len(target["labels"]) >= 2 and (target["labels"] == 1).any()
