"""Every image-file reader of the package and the detector is the one reader of :mod:`aias_augment.core.image_io`:
an EXIF-rotated JPEG decodes to the same upright pixels through each of them (PIL's ``exif_transpose`` and OpenCV's
own EXIF handling are the independent references), and a broken file is the reader's named error everywhere."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from PIL import Image, ImageOps

from aias_augment.apply.harmonize.pairs import read_image_rgb as harmonizer_read
from aias_augment.cli.offline_job import read_rgb as offline_read
from aias_augment.core.errors import AiasError
from aias_augment.core.image_io import CorruptImage, image_size, read_image, upright
from aias_augment.scenes.kitti import read_image_rgb as scene_read
from aias_augment.scenes.retrieval.sources import read_image as frame_read_bgr
from detection_eval.data import load_yolo_dir
from detection_eval.data import read_image_rgb as detector_read

READERS = {
    "core": lambda p: read_image(p),
    "scenes.kitti (kitti, nyu, dgp frames)": scene_read,
    "scenes.retrieval.sources (BGR frames)": lambda p: frame_read_bgr(p)[..., ::-1],
    "apply.harmonize.pairs": harmonizer_read,
    "cli.offline_job": offline_read,
    "detection_eval.data": detector_read,
    "detection_eval.data, reduced decode": lambda p: detector_read(p, min_long_side=1000),
}


def _picture(h: int = 48, w: int = 80) -> np.ndarray:
    """RGB uint8 with four distinct quadrants and a bright corner block: every flip and rotation is visible."""
    img = np.zeros((h, w, 3), np.uint8)
    img[: h // 2, : w // 2] = (250, 10, 10)
    img[: h // 2, w // 2 :] = (10, 250, 10)
    img[h // 2 :, : w // 2] = (10, 10, 250)
    img[h // 2 :, w // 2 :] = (240, 240, 240)
    img[:8, :8] = (250, 250, 0)
    return img


def _save(path, img: np.ndarray, orientation: int, **kw) -> None:
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(img).save(path, exif=exif.tobytes(), **kw)


def _pil_upright(path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(ImageOps.exif_transpose(im).convert("RGB"))


@pytest.mark.parametrize("orientation", range(1, 9))
def test_png_orientation_is_pils_exif_transpose(tmp_path, orientation):
    # lossless: the pixels must equal PIL's own decode turned by its exif_transpose, exactly
    p = tmp_path / "o.png"
    _save(p, _picture(), orientation)
    ref = _pil_upright(p)
    assert np.array_equal(read_image(p), ref)
    assert np.array_equal(upright(_picture(), orientation), ref)
    assert image_size(p) == (ref.shape[1], ref.shape[0])


@pytest.mark.parametrize("orientation", [3, 6, 8])
def test_jpeg_orientation_is_opencvs(tmp_path, orientation):
    # OpenCV's own EXIF handling (cv2.imread without IMREAD_IGNORE_ORIENTATION) is a second, independent reference
    p = tmp_path / "o.jpg"
    _save(p, _picture(), orientation, quality=95)
    assert np.array_equal(read_image(p), cv2.imread(str(p))[..., ::-1])
    assert np.array_equal(read_image(p, grey=True), cv2.imread(str(p), cv2.IMREAD_GRAYSCALE))


def test_every_reader_decodes_one_rotated_jpeg_upright_and_identically(tmp_path):
    p = tmp_path / "rot.jpg"
    _save(p, _picture(), 6, quality=95)  # stored 80 wide x 48 high, displayed 48 wide x 80 high
    ref = _pil_upright(p)
    assert ref.shape == (80, 48, 3)
    core = read_image(p)
    assert np.abs(core.astype(int) - ref.astype(int)).mean() < 2  # two JPEG decoders: near, not equal
    for name, read in READERS.items():
        assert np.array_equal(read(p), core), name
    assert image_size(p) == (48, 80)


def test_detector_records_and_reduced_decode_are_upright(tmp_path):
    root = tmp_path / "set"
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    stored = cv2.resize(_picture(), (800, 480), interpolation=cv2.INTER_NEAREST)
    _save(root / "images" / "a.jpg", stored, 8, quality=95)  # displayed 480 wide x 800 high
    (root / "labels" / "a.txt").write_text("0 0.5 0.25 0.5 0.5\n")
    (record,) = load_yolo_dir(root).records
    assert (record.width, record.height) == (480, 800)
    assert np.allclose(record.boxes_xyxy, [[120, 0, 360, 400]])
    small = detector_read(record.image_path, min_long_side=200)  # 1/4 scale keeps the long side at 200
    assert small.shape == (200, 120, 3)
    assert np.array_equal(small, cv2.imread(record.image_path, cv2.IMREAD_REDUCED_COLOR_4)[..., ::-1])


def test_a_truncated_jpeg_is_the_readers_error_everywhere(tmp_path):
    p = tmp_path / "cut.jpg"
    _save(p, _picture(), 1, quality=95)
    p.write_bytes(p.read_bytes()[:-200])  # OpenCV alone decodes it and fills the missing rows with grey
    for name, read in READERS.items():
        with pytest.raises(CorruptImage) as e:
            read(p)
        assert isinstance(e.value, AiasError) and "cut.jpg" in str(e.value) and "\n" not in str(e.value), name


def test_output_check_reads_sizes_with_the_reader(tmp_path):
    from aias_augment.adapters.boundary import check_output_record

    (tmp_path / "images").mkdir()
    rec = {"file_name": "a.jpg", "width": 48, "height": 80, "boxes": [], "labels": [], "inserted": []}
    _save(tmp_path / "images" / "a.jpg", _picture(), 6, quality=95)  # displayed 48 x 80
    assert check_output_record(rec, tmp_path) == []
    (tmp_path / "images" / "a.jpg").write_bytes(b"not an image")
    (err,) = check_output_record(rec, tmp_path)  # one line, no traceback
    assert err.startswith("image file a.jpg: corrupt image: ") and "\n" not in err
