"""Replay of the bounded door (working_resolution.insert_bounded) on a real 1920x1080 frame.

``insert_bounded`` analyses and plans on a <= 2 MP copy of a larger frame; the record keeps that working resolution
(``working_resolution``: full size, analysis size, bound), and ``insertion.replay.replay`` analyses the same copy the
same way, so the replayed image is the bounded door's output byte for byte. Without the field (a record written
before it existed) replay analyses the full frame it is given: the intrinsics estimated without K, the region mask
and the lighting differ, and so does the image. The control (an unbounded image) replays byte for byte.
"""

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from aias_augment import load_preset
from aias_augment.core.frame import Frame
from aias_augment.pipeline.bounded import ANALYSIS_MAX_PIXELS, insert_bounded
from aias_augment.pipeline.image import InsertionRecord
from aias_augment.pipeline.replay import replay

DATA = Path(os.environ.get("AIAS_DATA", "../shared/data"))
DGP_IMAGE = DATA / "dgp_scene" / "scene_01" / "rgb" / "CAMERA_01" / "15569195938415230.jpg"


def _rgb(path: Path) -> np.ndarray:
    if not path.is_file():
        pytest.skip(f"{path} missing (AIAS_DATA)")
    return np.ascontiguousarray(cv2.imread(str(path))[:, :, ::-1])


def frame_1920x1080() -> np.ndarray:
    """The DGP CAMERA_01 frame (1936x1216) centre-cropped to 16:9 and area-resized to 1920x1080 (2.07 MP)."""
    img = _rgb(DGP_IMAGE)
    h, w = img.shape[:2]
    ch = int(round(w * 9 / 16))
    top = (h - ch) // 2
    return cv2.resize(np.ascontiguousarray(img[top : top + ch]), (1920, 1080), interpolation=cv2.INTER_AREA)


def _replayed(result, image, cfg) -> np.ndarray:
    record = json.loads(json.dumps(result.record.to_dict()))  # as read back from records/NNNNNN.json
    return replay(record, Frame(image, None), cfg).image


@pytest.mark.parametrize("preset", ["fast", "balanced"])
def test_replay_reproduces_bounded_door_on_1920x1080(preset):
    big = frame_1920x1080()
    assert big.shape[0] * big.shape[1] > ANALYSIS_MAX_PIXELS  # the bounded path really runs
    cfg = load_preset(preset)
    result = insert_bounded(big, None, None, np.random.default_rng(0), cfg)
    assert result.inserted_labels  # something was drawn, so the comparison is not vacuous
    wr = result.record.working_resolution
    assert wr.image_size == (1920, 1080) and wr.analysis_size[0] * wr.analysis_size[1] <= ANALYSIS_MAX_PIXELS
    assert np.array_equal(_replayed(result, big, cfg), result.image)


def test_replay_of_a_bounded_record_without_its_working_resolution_differs():
    """The recorded working resolution is what makes the bounded replay exact: the same record with the field
    removed (as a record written before it existed) replays the old way, analysing the full frame, and differs."""
    big = frame_1920x1080()
    cfg = load_preset("fast")
    result = insert_bounded(big, None, None, np.random.default_rng(0), cfg)
    record = json.loads(json.dumps(result.record.to_dict()))
    del record["working_resolution"]
    assert not np.array_equal(replay(record, Frame(big, None), cfg).image, result.image)


def test_record_round_trips_with_and_without_working_resolution():
    big = frame_1920x1080()
    cfg = load_preset("fast")
    bounded = insert_bounded(big, None, None, np.random.default_rng(0), cfg).record
    d = json.loads(json.dumps(bounded.to_dict()))
    assert d["working_resolution"]["image_size"] == [1920, 1080]
    assert json.dumps(InsertionRecord.from_dict(d).to_dict()) == json.dumps(d)
    assert InsertionRecord.from_dict(d).working_resolution == bounded.working_resolution
    small = cv2.resize(big, (960, 540), interpolation=cv2.INTER_AREA)
    unbounded = insert_bounded(small, None, None, np.random.default_rng(0), cfg).record.to_dict()
    assert unbounded["working_resolution"] is None
    old = {k: v for k, v in unbounded.items() if k != "working_resolution"}  # a record from before the field
    assert InsertionRecord.from_dict(old).working_resolution is None


def test_replay_reproduces_unbounded_door():
    """Control: an image under the bound (through the same door) replays byte for byte."""
    small = cv2.resize(frame_1920x1080(), (960, 540), interpolation=cv2.INTER_AREA)
    cfg = load_preset("fast")
    result = insert_bounded(small, None, None, np.random.default_rng(0), cfg)
    assert result.inserted_labels
    assert not np.array_equal(result.image, small)
    assert np.array_equal(_replayed(result, small, cfg), result.image)
