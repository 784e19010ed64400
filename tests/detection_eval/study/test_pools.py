from __future__ import annotations

import numpy as np

from detection_eval.study.config import InsertionStudyConfig, StudyConfig
from detection_eval.study.splits import thin_cone_images


def test_closeup_crop_is_a_slice_with_the_target_height_and_exact_boxes():
    from detection_eval.study.pools import closeup_crop

    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (360, 640, 3), dtype=np.uint8)
    boxes = np.array(
        [
            [300.0, 200.0, 330.0, 260.0],  # tallest: 60 px = 1/6 of the height
            [100.0, 250.0, 110.0, 270.0],
        ]
    )  # far left: falls outside most crops
    for seed in range(20):
        crop, out, info = closeup_crop(img, boxes, (0.4,), np.random.default_rng(seed), min_side_px=100)
        ch, cw = crop.shape[:2]
        x0, y0, w0, h0 = info["crop_xywh"]
        assert np.array_equal(crop, img[y0 : y0 + h0, x0 : x0 + w0])  # no resampling: a slice
        assert abs(cw / ch - 640 / 360) < 0.02  # the image's aspect
        assert abs(60 / ch - 0.4) < 0.01  # the tallest box now 0.4 of the frame
        np.testing.assert_allclose(out[0], boxes[0] - [x0, y0, x0, y0])  # whole, moved by the origin
        assert len(out) + info["dropped_boxes"] == 2
    # A target below the current size, or no boxes: unchanged.
    same, out, info = closeup_crop(img, boxes, (0.1,), rng)
    assert same is img and info["zoom"] == 1.0 and np.array_equal(out, boxes)
    # The short side never goes below min_side_px: the zoom is capped.
    crop, _, info = closeup_crop(img, boxes, (0.95,), rng, min_side_px=160)
    assert crop.shape[0] >= 159 and info["zoom"] <= 360 / 160 + 0.01


def _yolo_cones(root, n_cone, n_empty):
    """A tiny YOLO dataset: grey-green noise roads, orange triangle cones on the cone images."""
    import cv2

    from tests.aias_augment.assets.bank.test_lift import draw_cone, noise_background

    (root / "images" / "train").mkdir(parents=True)
    (root / "labels" / "train").mkdir(parents=True)
    for i in range(n_cone + n_empty):
        img = noise_background(240, 320, i)
        lines = []
        if i < n_cone:
            b = draw_cone(img, 100 + 20 * i, 200, 120, 32)
            lines.append(f"0 {(b[0] + b[2]) / 640} {(b[1] + b[3]) / 480} {(b[2] - b[0]) / 320} {(b[3] - b[1]) / 240}")
        cv2.imwrite(str(root / "images" / "train" / f"im{i}.png"), img[..., ::-1])
        (root / "labels" / "train" / f"im{i}.txt").write_text("\n".join(lines))


def test_copy_paste_pool_uses_only_the_seeds_own_instances(tmp_path):
    import json

    from detection_eval.data import load_yolo_dir
    from detection_eval.study.pools import generate_arm_set

    _yolo_cones(tmp_path / "data", 4, 6)
    train = load_yolo_dir(tmp_path / "data", "train", ("cone",))
    cfg = StudyConfig(
        dataset=str(tmp_path / "data"),
        keep_fraction=0.5,
        arms=("original", "copy_paste"),
        amounts=(3,),
        insertion=InsertionStudyConfig(pool_size=3, max_objects=2),
        cache_dir=str(tmp_path / "cache"),
    )
    seen = {}
    for seed in (0, 1):
        base, empty = thin_cone_images(train, cfg.keep_fraction, seed)
        out = generate_arm_set(cfg, "copy_paste", train, empty, seed, base)
        done = json.loads((out / "done.json").read_text())
        own = sorted(r.image_path.rsplit("/", 1)[1] for r in base.records if len(r.labels))
        assert sorted(done["sources"]) == own and done["num_images"] == 3 and done["num_boxes"] >= 3
        seen[seed] = own
        pool = load_yolo_dir(out, names=("cone",))
        for r in pool.records:
            assert np.all(r.boxes_xyxy[:, :2] >= 0) and np.all(r.boxes_xyxy[:, 2] <= r.width)
            assert np.all(r.boxes_xyxy[:, 3] <= r.height)
    assert seen[0] != seen[1]


def test_paste_instances_changes_only_the_pasted_boxes():
    from aias_augment.assets.bank.lift import cut_out
    from detection_eval.copy_paste import paste_instances
    from tests.aias_augment.assets.bank.test_lift import draw_cone, noise_background

    src = noise_background(240, 320)
    cut, _ = cut_out(src, draw_cone(src, 160, 200, 120, 32))
    bg = np.full((200, 300, 3), 77, np.uint8)
    out, boxes = paste_instances(bg, [cut], np.random.default_rng(0), (0.3, 0.5), n_objects=3)
    assert len(boxes) >= 2
    inside = np.zeros(bg.shape[:2], bool)
    for x0, y0, x1, y1 in boxes.astype(int):
        assert 0 <= x0 < x1 <= 300 and 0 <= y0 < y1 <= 200
        assert 0.25 * 200 <= y1 - y0 <= 0.55 * 200
        inside[max(0, y0 - 2) : y1 + 2, max(0, x0 - 2) : x1 + 2] = True
    assert np.all(out[~inside] == 77)  # soft edges stay within 2 px of the box
    assert np.any(out[inside] != 77)


def test_mixed_pool_is_its_sources_copies_byte_for_byte(tmp_path):
    import json

    from detection_eval.data import load_yolo_dir
    from detection_eval.study.pools import generate_arm_set, mixed_pool_sources

    # The coin of a longer pool starts with that of a shorter one (amount axes share their first copies).
    assert mixed_pool_sources(0, 200, 2)[:60] == mixed_pool_sources(0, 60, 2)
    assert 0.4 < np.mean(mixed_pool_sources(0, 200, 2)) < 0.6
    _yolo_cones(tmp_path / "data", 2, 6)
    train = load_yolo_dir(tmp_path / "data", "train", ("cone",))
    cfg = StudyConfig(
        dataset=str(tmp_path / "data"),
        keep_fraction=0.5,
        arms=("original", "inserted_mixed_naive"),
        amounts=(6,),
        insertion=InsertionStudyConfig(pool_size=6, max_objects=1, max_side_px=320),
        cache_dir=str(tmp_path / "cache"),
    )
    _, empty = thin_cone_images(train, cfg.keep_fraction, 0)
    out = generate_arm_set(cfg, "inserted_mixed_naive", train, empty)
    which = mixed_pool_sources(0, 6, 2)
    assert set(which) == {0, 1}  # both kinds in this pool
    sources = ("inserted", "naive_paste_procedural")
    done = json.loads((out / "done.json").read_text())
    assert done["copies_by_source"] == {s: which.count(i) for i, s in enumerate(sources)}
    by_copy = {e["copy"]: e for e in json.loads((out / "manifest.json").read_text())}
    for j, k in enumerate(which):
        src = tmp_path / "cache" / sources[k] / "pool"
        src_entry = {e["copy"]: e for e in json.loads((src / "manifest.json").read_text())}[j]
        assert by_copy[j]["source_arm"] == sources[k] and by_copy[j]["background"] == src_entry["background"]
        a = (out / "images" / by_copy[j]["image"]).read_bytes()
        assert a == (src / "images" / src_entry["image"]).read_bytes()
    assert len(load_yolo_dir(out, names=("cone",)).records) == done["num_images"] == 6
    # A second call reuses the pool as it is.
    stamp = (out / "done.json").stat().st_mtime_ns
    generate_arm_set(cfg, "inserted_mixed_naive", train, empty)
    assert (out / "done.json").stat().st_mtime_ns == stamp


def test_pipeline_pool_is_what_the_cli_runner_writes(tmp_path):
    """A pipeline arm's copy j is the CLI's offline run (``aias_augment.cli.offline.run``, JPEG 95) of the pool's
    background j with ``seed = pool_seed``: the same bytes, the same boxes; nothing of the runner's work is left."""
    import json

    import cv2

    from aias_augment.cli.dataset_out import DatasetOutput, ImageOut
    from aias_augment.cli.offline import run
    from aias_augment.cli.offline_job import Item
    from detection_eval.data import load_yolo_dir
    from detection_eval.study.arms import insertion_config_for_arm
    from detection_eval.study.pools import generate_arm_set, pool_background
    from detection_eval.study.splits import pool_backgrounds

    _yolo_cones(tmp_path / "data", 2, 3)
    train = load_yolo_dir(tmp_path / "data", "train", ("cone",))
    cfg = StudyConfig(
        dataset=str(tmp_path / "data"),
        keep_fraction=0.5,
        arms=("original", "naive_paste"),
        amounts=(2,),
        insertion=InsertionStudyConfig(pool_size=2, max_objects=2, max_side_px=200, pool_seed=3),
        cache_dir=str(tmp_path / "cache"),
    )
    _, empty = thin_cone_images(train, cfg.keep_fraction, 0)
    out = generate_arm_set(cfg, "naive_paste", train, empty)
    assert not (out / "runner").exists()
    entries = json.loads((out / "manifest.json").read_text())
    assert [e.get("failed") for e in entries] == [None, None]
    # The CLI's run of the same downscaled backgrounds, written losslessly as its inputs.
    (tmp_path / "bg").mkdir()
    items = []
    for j, i in enumerate(pool_backgrounds(empty, 3, 2)):
        image = pool_background(train.records[i].image_path, 200)
        assert max(image.shape[:2]) == 200
        path = tmp_path / "bg" / f"{j}.png"
        cv2.imwrite(str(path), image[..., ::-1])
        items.append(Item(path=str(path)))
    ins_cfg = insertion_config_for_arm(cfg, "naive_paste", train)
    run(items, ins_cfg, 3, str(tmp_path / "cli"), output=DatasetOutput(image=ImageOut("jpg", 95)))
    pool = {r.image_path.rsplit("/", 1)[1]: r for r in load_yolo_dir(out, names=("cone",)).records}
    for j, e in enumerate(entries):
        rec = json.loads((tmp_path / "cli" / "records" / f"{j:06d}.json").read_text())
        cli_bytes = (tmp_path / "cli" / "images" / rec["file_name"]).read_bytes()
        assert (out / "images" / e["image"]).read_bytes() == cli_bytes
        b = np.asarray(rec["boxes"], float).reshape(-1, 4)
        np.testing.assert_allclose(pool[e["image"]].boxes_xyxy, np.c_[b[:, :2], b[:, :2] + b[:, 2:]], atol=1e-3)
        assert e["boxes"] == len(b) >= 1
