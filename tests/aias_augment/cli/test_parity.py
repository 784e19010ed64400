"""CLI parity: the offline CLI takes what the Python API takes: unlabelled ``--images``, the user's meshes
(``--assets``, ``--assets-bank``), the sun from position and time (``--sun-from``), an HDR environment map
(``--envmap``, the scene fact ``envmap``) and a config file (``--config``);
a bad value is one line on stderr and exit 2 before any image is processed; other meshes are another run.

Real runs of ``aias_augment.cli.augment.main`` on 160x120 road-like images with meshes written by trimesh (fast preset)."""

import json
import pickle

import cv2
import numpy as np
import pytest
import trimesh

from aias_augment.assets.asset import DEFAULT_ASSETS, PathAssets
from aias_augment.cli.augment import asset_paths, main
from aias_augment.core.config import data_root
from tests.aias_augment.cli.test_offline_validate import road_picture

FAST = ["--preset", "fast", "--per-image", "1", "--seed", "3"]


def _backgrounds(tmp_path, n=2):
    d = tmp_path / "backgrounds"
    d.mkdir()
    for i in range(n):
        cv2.imwrite(str(d / f"bg{i}.png"), road_picture(seed=i))
    (d / "notes.txt").write_text("not an image")
    return d


def _box_mesh(path, extents=(0.7, 0.7, 0.7), rgb=(255, 0, 255)):
    m = trimesh.creation.box(extents=extents)
    m.visual.face_colors = np.array([*rgb, 255], np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    m.export(path)
    return path


def _records(out):
    return [json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))]


def test_unlabelled_images_with_own_mesh(tmp_path):
    """--images alone + --assets: every output box is an inserted crate; the records name the mesh; its colour and
    size are the mesh's; two workers give the same bytes (the asset source pickles into them)."""
    images = _backgrounds(tmp_path)
    mesh = _box_mesh(tmp_path / "meshes" / "crate.glb")
    args = ["--images", str(images), "--assets", f"crate={mesh}", *FAST]
    assert main(args + ["--out", str(tmp_path / "out")]) == 0
    coco = json.loads((tmp_path / "out" / "annotations.json").read_text())
    assert [c["name"] for c in coco["categories"]] == ["crate"]  # only the inserted category
    assert len(coco["images"]) == 2 and len(coco["annotations"]) >= 1
    assert all(a["inserted"] for a in coco["annotations"])
    for rec in _records(tmp_path / "out"):
        assert rec["labels"] == ["crate"] * len(rec["labels"]) and all(rec["inserted"])
        for p in rec["placements"]:
            assert p["asset_source"] == str(mesh) and p["category"] == "crate"
            assert p["height_m"] == pytest.approx(0.7, abs=1e-3)  # the mesh's own size, in metres
        img = cv2.imread(str(tmp_path / "out" / "images" / rec["file_name"]))[..., ::-1].astype(int)
        x, y, w, h = (int(round(v)) for v in rec["boxes"][0])
        patch = img[y + h // 4 : y + 3 * h // 4, x + w // 4 : x + 3 * w // 4].reshape(-1, 3)
        r, g, b = np.median(patch, axis=0)
        assert r > g + 40 and b > g + 40, (r, g, b)  # magenta, not the grey road
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert manifest["options"]["assets"]["crate"][0][0] == str(mesh)
    # The asset source goes into spawned workers (and Ray tasks) by pickle: same outputs.
    assert main(args + ["--out", str(tmp_path / "w2"), "--workers", "2"]) == 0
    assert (tmp_path / "out" / "annotations.json").read_bytes() == (tmp_path / "w2" / "annotations.json").read_bytes()
    for p in sorted((tmp_path / "out" / "images").iterdir()):
        assert p.read_bytes() == (tmp_path / "w2" / "images" / p.name).read_bytes()


def test_asset_sources_parse_and_pickle(tmp_path):
    """A folder of meshes gives each mesh in it; a bank folder (bank.json of `aias-assets from-labels`) adds its
    assets; the PathAssets made of them pickles (spawn pool, Ray) and draws the user's mesh."""
    a = _box_mesh(tmp_path / "cones" / "a.obj")
    b = _box_mesh(tmp_path / "cones" / "sub" / "b.glb")
    (tmp_path / "cones" / "readme.txt").write_text("x")
    lifted = _box_mesh(tmp_path / "bank" / "assets" / "cone_000.glb")
    (tmp_path / "bank" / "bank.json").write_text(
        json.dumps({"report": {"assets": [{"category": "cone", "file": "assets/cone_000.glb"}], "rejected": []}})
    )
    paths = asset_paths([f"cone={tmp_path / 'cones'}", f"crate={b}"], str(tmp_path / "bank"))
    assert paths == {"cone": [str(a), str(b), str(lifted)], "crate": [str(b)]}
    bank = pickle.loads(pickle.dumps(PathAssets(paths)))
    cloudpickle = pytest.importorskip("cloudpickle")
    bank = cloudpickle.loads(cloudpickle.dumps(bank))
    asset = bank.sample("crate", np.random.default_rng(0))
    assert asset.source == str(b) and asset.height_m == pytest.approx(0.7, abs=1e-6)


BAD = [
    (["--assets", "crate"], "expected CATEGORY=PATH"),
    (["--assets", "crate={tmp}/missing.glb"], "missing.glb"),
    (["--assets", "crate={tmp}/backgrounds"], "no mesh files"),
    (["--assets-bank", "{tmp}/backgrounds"], "no bank.json"),
    (["--sun-from", "95,11.6,2024-06-01T12:00:00Z,90"], "'lat'"),
    (["--sun-from", "48.1,11.6,2024-13-45T99:00,90"], "'utc'"),
    (["--sun-from", "48.1,11.6,2024-06-01T12:00:00Z"], "LAT,LON,UTC,HEADING"),
    (["--sun-from", "48.1,11.6,2024-06-01T12:00:00Z,east"], "'heading_deg'"),
    (["--config", "{tmp}/bad.yaml"], "bad.yaml: InsertionConfig.placement_cfg.max_tries"),
    (["--config", "{tmp}/unknown.yaml"], "unknown.yaml: InsertionConfig: unknown config keys ['shadows']"),
    (["--config", "{tmp}/missing.yaml"], "missing.yaml"),
    (["--categories", "unicorn"], "unknown categories ['unicorn']"),
    (["--envmap", "{tmp}/missing.hdr"], "missing.hdr"),
    (["--envmap", "{tmp}/bad.yaml"], "unsupported HDR file type"),
]


@pytest.mark.parametrize("extra, message", BAD)
def test_bad_values_are_one_line_exit_2_before_any_image(tmp_path, capsys, extra, message):
    images = _backgrounds(tmp_path)
    (tmp_path / "bad.yaml").write_text("shadow: false\nplacement_cfg:\n  max_tries: many\n")
    (tmp_path / "unknown.yaml").write_text("shadows: false\n")
    extra = [e.format(tmp=tmp_path) for e in extra]
    out = tmp_path / "out"
    assert main(["--images", str(images), *extra, *FAST, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("aias-augment: error: ") and message in err[-1], err
    assert not out.exists()  # nothing processed, nothing written


def test_changed_mesh_is_another_run_never_reused_records(tmp_path, capsys):
    """The manifest holds each asset's content hash: the same path with other bytes is refused as another run,
    and --overwrite redoes every record with the new mesh."""
    images = _backgrounds(tmp_path, n=1)
    mesh = _box_mesh(tmp_path / "crate.glb")
    out = tmp_path / "out"
    args = ["--images", str(images), "--assets", f"crate={mesh}", *FAST, "--out", str(out)]
    assert main(args) == 0
    rec = out / "records" / "000000.json"
    before = json.loads(rec.read_text())
    assert main(args) == 0 and json.loads(rec.read_text()) == before  # same meshes: resumed, not redone
    _box_mesh(mesh, extents=(0.5, 1.1, 0.5), rgb=(0, 200, 0))  # same path, another mesh (glTF: y up)
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "holds another run" in err and "assets" in err
    assert json.loads(rec.read_text()) == before  # refused: untouched
    assert main(args + ["--overwrite"]) == 0
    after = json.loads(rec.read_text())
    assert [p["height_m"] for p in after["placements"]] == pytest.approx([1.1] * len(after["placements"]), abs=1e-3)
    assert after["placements"] and after["placements"] != before["placements"]


@pytest.mark.skipif(not (data_root() / DEFAULT_ASSETS["traffic_cone"][0]).exists(), reason="shared data not present")
def test_sun_from_and_config_file(tmp_path):
    """--sun-from puts position, time and heading into every image's scene facts (the lighting's sun comes from
    them); --config's fields apply over the preset, --per-image over the file."""
    images = _backgrounds(tmp_path, n=1)
    cfg = tmp_path / "mine.yaml"
    cfg.write_text("max_objects: 3\nshadow: false\nplacement_cfg:\n  max_tries: 17\n")
    out = tmp_path / "out"
    assert (
        main(
            [
                "--images",
                str(images),
                "--sun-from",
                "48.1,11.6,2024-06-01T10:00:00Z,90",
                "--config",
                str(cfg),
                *FAST,
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rec = _records(out)[0]
    assert rec["lighting"]["source"] == "metadata" and rec["lighting"]["sun_direction_in_cam"] is not None
    c = rec["config"]
    assert (c["shadow"], c["placement_cfg"]["max_tries"], c["max_objects"], c["categories"]) == (
        False,
        17,
        1,
        ["traffic_cone"],
    )
    # The sun's azimuth: at 10:00 UTC in Munich (noon local) the sun is about south, the camera faces east
    # (heading 90): the sun is to the camera's right (+x in OpenCV camera coordinates) and above (-y).
    s = rec["lighting"]["sun_direction_in_cam"]
    assert s[0] > 0.3 and s[1] < -0.3, s
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["options"]["sun_from"]["utc"] == "2024-06-01T10:00:00Z"


# ------------------------------------------------------------------------------- --envmap (scene fact 'envmap')
def _sun_envmap(azimuth_deg, elevation_deg, h=64):
    """A dim sky over a darker ground with a small very bright sun at (azimuth, elevation) of the env frame."""
    from aias_augment.analyse.lighting.envmap import azimuth_elevation_to_direction, pixel_directions

    d = azimuth_elevation_to_direction(np.radians(azimuth_deg), np.radians(elevation_deg))
    dirs = pixel_directions(h, 2 * h)
    rad = np.full((h, 2 * h, 3), 0.3, np.float32)
    rad[dirs[..., 2] < 0] = 0.1
    rad[dirs @ d > np.cos(np.radians(3.0))] = 2000.0
    return rad, d


def test_envmap_fact_is_the_scene_lighting_and_part_of_the_cache_key():
    from aias_augment.analyse.analysis import scene_key
    from aias_augment.analyse.cache import SceneCache
    from aias_augment.analyse.lighting.envmap import cam_from_env_look
    from aias_augment.core.envmap import EnvironmentMap
    from aias_augment.core.frame import Frame
    from aias_augment.core.scene_inputs import SceneInputs
    from aias_augment.pipeline.bounded import insert_bounded
    from aias_augment.pipeline.image import load_preset

    cam_from_env = cam_from_env_look(0.0)  # a level camera looking at the map's centre column
    rad, d = _sun_envmap(-40.0, 35.0)  # ahead-right of the camera, 35 deg up
    env = EnvironmentMap(rad, cam_from_env)
    image = road_picture()[..., ::-1].copy()
    cfg = load_preset("fast", categories=("traffic_cone",), max_objects=1)
    cache = SceneCache()
    for scene in (SceneInputs(envmap=env), SceneInputs(envmap=rad, world_from_env=cam_from_env)):
        res = insert_bounded(
            image, None, None, np.random.default_rng(0), cfg, scene=scene, scene_cache=cache, n_objects=0
        )
        light = res.record.to_dict()["lighting"]
        assert light["source"] == "envmap" and light["dominant_sun"]
        want = cam_from_env @ d
        assert np.degrees(np.arccos(np.clip(np.dot(light["sun_direction_in_cam"], want), -1, 1))) < 3.0
    insert_bounded(
        image, None, None, np.random.default_rng(1), cfg, scene=SceneInputs(envmap=env), scene_cache=cache, n_objects=0
    )
    assert cache.misses == 2 and cache.hits == 1  # the same map again: the cached analysis
    # The key holds the map's pixels: another sun (same shape, same repr) is another analysis.
    rad2, _ = _sun_envmap(60.0, 20.0)
    keys = {
        scene_key(Frame(image, None, meta=m), cfg)
        for m in ({}, {"envmap": env}, {"envmap": EnvironmentMap(rad2, cam_from_env)}, {"envmap": EnvironmentMap(rad)})
    }
    assert len(keys) == 4
    with pytest.raises(ValueError, match="'envmap'"):
        SceneInputs(envmap=np.ones((4, 4, 3))).checked((1, 1))


def test_envmap_option(tmp_path):
    from aias_augment.analyse.lighting.envmap import cam_from_env_look
    from aias_augment.core.hdr import write_hdr_image

    images = _backgrounds(tmp_path, n=1)
    mesh = _box_mesh(tmp_path / "crate.glb")
    rad, d = _sun_envmap(30.0, 40.0)  # ahead-left
    write_hdr_image(tmp_path / "sky.hdr", rad)
    out = tmp_path / "out"
    assert (
        main(
            [
                "--images",
                str(images),
                "--assets",
                f"crate={mesh}",
                "--envmap",
                str(tmp_path / "sky.hdr"),
                *FAST,
                "--out",
                str(out),
            ]
        )
        == 0
    )
    light = _records(out)[0]["lighting"]
    assert light["source"] == "envmap"
    s = np.asarray(light["sun_direction_in_cam"])
    assert np.degrees(np.arccos(np.clip(s @ (cam_from_env_look(0.0) @ d), -1, 1))) < 3.0 and s[0] < 0
    assert json.loads((out / "manifest.json").read_text())["options"]["envmap"][0] == str(tmp_path / "sky.hdr")


def test_config_file_naive_share_is_recorded_per_image(tmp_path):
    """``naive_share`` from --config: each image's record says how it was made, and the naive ones skipped the
    stages a naive paste skips (the rest did not)."""
    images = _backgrounds(tmp_path, n=5)
    mesh = _box_mesh(tmp_path / "meshes" / "crate.glb")
    cfg = tmp_path / "share.yaml"
    cfg.write_text("naive_share: 0.5\n")
    out = tmp_path / "out"
    assert (
        main(["--images", str(images), "--assets", f"crate={mesh}", "--config", str(cfg), *FAST, "--out", str(out)])
        == 0
    )
    recs = _records(out)
    assert len(recs) == 5 and all(r["config"]["naive_share"] == 0.5 for r in recs)
    for i, r in enumerate(recs):  # image i draws from default_rng([seed, i]); its first uniform is the coin
        assert r["mode"] == ("naive_paste" if np.random.default_rng([3, i]).random() < 0.5 else "pipeline")
        assert ("placement" in r["skipped_stages"]) == (r["mode"] == "naive_paste")
    assert {r["mode"] for r in recs} == {"pipeline", "naive_paste"}  # seed 3: both kinds, so both were checked
