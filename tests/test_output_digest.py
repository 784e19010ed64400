"""tools/output_digest.py's digests and comparison (the pipeline runs themselves are the script's job: too slow
for the unit tests)."""

import importlib.util
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("output_digest", ROOT / "tools" / "output_digest.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_image_digest_sees_one_level_and_the_shape():
    tool = _tool()
    a = np.zeros((4, 6, 3), np.uint8)
    b = a.copy()
    b[3, 5, 2] = 1
    assert tool.sha_image(a) == tool.sha_image(a.copy())
    assert tool.sha_image(a) != tool.sha_image(b)
    assert tool.sha_image(a) != tool.sha_image(a.reshape(6, 4, 3))


def test_box_digest_rounds_to_1e6_and_sees_labels():
    tool = _tool()
    boxes = np.array([[1.0, 2.0, 3.0, 4.0]])
    assert tool.sha_boxes(boxes, ["cone"]) == tool.sha_boxes(boxes + 1e-9, ["cone"])
    assert tool.sha_boxes(boxes, ["cone"]) != tool.sha_boxes(boxes + 1e-5, ["cone"])
    assert tool.sha_boxes(boxes, ["cone"]) != tool.sha_boxes(boxes, ["barrel"])
    assert tool.sha_boxes(np.zeros((0, 4)), []) == tool.sha_boxes([], [])


def test_compare_lists_every_differing_case():
    tool = _tool()
    d = {"image_sha256": "a", "boxes_sha256": "b"}
    expected = {"same": d, "image": d, "boxes": d, "gone": d}
    got = {"same": d, "image": {**d, "image_sha256": "x"}, "boxes": {**d, "boxes_sha256": "y"}, "new": d}
    assert tool.compare(expected, got) == [
        "boxes: boxes_sha256 differ",
        "gone: missing case",
        "image: image_sha256 differ",
        "new: new case",
    ]
    assert tool.compare(expected, expected) == []


def test_committed_digests_cover_every_case_of_the_reference_set():
    """The committed json has exactly the script's cases (names only: computing them is --check's job)."""
    import json

    tool = _tool()
    committed = json.loads((ROOT / "results" / "architecture" / "digests.json").read_text())
    doors = {name.split("/")[0] for name in committed}
    assert doors == {"insert_into_image", "insert_bounded", "InsertObjects", "insert_into_clip"}
    assert {n.split("/")[2] for n in committed if n.startswith(("insert_into_image", "insert_bounded"))} == set(
        tool.PRESETS
    )
