import json
import re
import shutil
from collections import Counter
from pathlib import Path

import pytest

from aias_augment.evaluation.abstudy.build import StudyError, build_study, load_study, match_entries, orient, read_arm
from tests.aias_augment.evaluation.abstudy.helpers import SOURCES, image_arms, make_clip, make_image_arm


def _pairs_by_comparison(study):
    out = {}
    for pid, k in study.key.items():
        m, o = orient(study.arms, study.baseline, k["left"], k["right"])
        out.setdefault((m, o), []).append((pid, k))
    return out


def test_read_image_arm_skips_skipped_records(tmp_path):
    arm = make_image_arm(tmp_path / "a", SOURCES, seed=1, skipped=(2,))
    entries = read_arm(arm)
    assert [e.key for e in entries] == [s for i, s in enumerate(SOURCES) if i != 2]
    assert all(e.kind == "image" and len(e.files) == 1 and e.files[0].is_file() for e in entries)


def test_baseline_design_pairs_every_arm_with_the_baseline_balanced(tmp_path):
    arms = image_arms(tmp_path, 3)
    summary = build_study(arms, tmp_path / "study", seed=3)
    study = load_study(tmp_path / "study")
    assert study.baseline == "naive_paste" and study.arms == ["naive_paste", "full", "no_shadow"]
    assert summary["pairs"] == 10
    assert summary["comparisons"] == {"full vs naive_paste": 5, "no_shadow vs naive_paste": 5}
    by = _pairs_by_comparison(study)
    assert set(by) == {("full", "naive_paste"), ("no_shadow", "naive_paste")}
    for rows in by.values():
        assert sorted(k["source"] for _, k in rows) == sorted(SOURCES)
        base_left = sum(k["left"] == "naive_paste" for _, k in rows)
        assert base_left in (2, 3)  # 5 pairs: as balanced as an odd count allows
    # what the page sees names no arm: ids are random tokens, media are content hashes
    public = json.dumps(study.meta["pairs"])
    for arm in study.arms:
        assert arm not in public
    assert all(len(pid) == 12 and int(pid, 16) >= 0 for pid in study.pairs)
    # each side's file is a byte copy of that arm's output for that source
    for pid, k in study.key.items():
        p = study.pairs[pid]
        i = SOURCES.index(k["source"])
        for side, arm in (("left", k["left"]), ("right", k["right"])):
            src = tmp_path / arm / "images" / f"{i:06d}_{Path(k['source']).stem}.png"
            assert (study.root / p[side][0]).read_bytes() == src.read_bytes()


def test_all_pairs_design_and_orientation(tmp_path):
    arms = image_arms(tmp_path, 3)
    build_study(arms, tmp_path / "study", design="all-pairs", baseline="naive_paste")
    study = load_study(tmp_path / "study")
    by = _pairs_by_comparison(study)
    # against the baseline the other arm is the method; between two others, the one listed first
    assert set(by) == {("full", "naive_paste"), ("no_shadow", "naive_paste"), ("full", "no_shadow")}
    assert all(len(v) == 5 for v in by.values())


def test_balance_over_many_pairs_and_seeded(tmp_path):
    sources = [f"/d/img_{i:03d}.jpg" for i in range(40)]
    arms = [make_image_arm(tmp_path / n, sources, seed=k + 1) for k, n in enumerate(["base", "m"])]
    build_study(arms, tmp_path / "s1", seed=7)
    build_study(arms, tmp_path / "s2", seed=7)
    build_study(arms, tmp_path / "s3", seed=8)
    s1, s2, s3 = (load_study(tmp_path / s) for s in ("s1", "s2", "s3"))
    assert Counter(k["left"] for k in s1.key.values()) == {"base": 20, "m": 20}
    assert s1.meta == s2.meta and s1.key == s2.key  # same seed, same study
    assert s1.key != s3.key
    # the order is shuffled: not the source order
    assert [s1.key[p["id"]]["source"] for p in s1.meta["pairs"]] != sources


def test_match_by_file_name_when_paths_differ(tmp_path):
    a = make_image_arm(tmp_path / "a", SOURCES, seed=1)
    b = make_image_arm(tmp_path / "b", [s.replace("/data/roads", "../roads") for s in SOURCES], seed=2)
    assert len(match_entries(read_arm(a), read_arm(b))) == len(SOURCES)
    assert build_study([a, b], tmp_path / "s")["pairs"] == len(SOURCES)


def test_identical_outputs_are_left_out(tmp_path):
    a = make_image_arm(tmp_path / "a", SOURCES, seed=1)
    b = make_image_arm(tmp_path / "b", SOURCES, seed=2)
    c = make_image_arm(tmp_path / "c", SOURCES, seed=0, same_as=a, same_idx=(1, 3))
    s = build_study([a, b, c], tmp_path / "s", design="all-pairs")
    assert s["identical_left_out"] == 2
    assert s["comparisons"] == {"b vs a": 5, "c vs a": 3, "b vs c": 5}
    same = make_image_arm(tmp_path / "same", SOURCES, seed=0, same_as=a)
    with pytest.raises(StudyError, match="no source with different outputs"):
        build_study([a, same], tmp_path / "s2")


def test_clip_arms_single_and_folder(tmp_path):
    one_a = make_clip(tmp_path / "A", "/clips/drive.mp4", seed=1, n_frames=4, fps=12)
    one_b = make_clip(tmp_path / "B", "/clips/drive.mp4", seed=2, n_frames=4, fps=12)
    build_study([one_a, one_b], tmp_path / "s1")
    s = load_study(tmp_path / "s1")
    (p,) = s.meta["pairs"]
    assert p["kind"] == "clip" and p["fps"] == 12 and len(p["left"]) == len(p["right"]) == 4
    # frames keep their order
    k = s.key[p["id"]]
    arm_dir = {"A": one_a, "B": one_b}[k["left"]]
    assert [(s.root / f).read_bytes() for f in p["left"]] == [
        (arm_dir / "frames" / f"{i:06d}.jpg").read_bytes() for i in range(4)
    ]
    for arm, seed in (("X", 3), ("Y", 4)):
        for j in range(3):
            make_clip(tmp_path / arm / f"clip{j}", f"/clips/c{j}.mp4", seed=seed * 10 + j)
    assert build_study([tmp_path / "X", tmp_path / "Y"], tmp_path / "s2")["pairs"] == 3


@pytest.mark.parametrize(
    "case", ["one_arm", "dup_names", "bad_name", "unknown_baseline", "no_shared", "mixed", "not_an_arm", "bad_design"]
)
def test_build_errors(tmp_path, case):
    a = make_image_arm(tmp_path / "a", SOURCES, seed=1)
    b = make_image_arm(tmp_path / "b", SOURCES, seed=2)
    kw, arms = {}, [a, b]
    if case == "one_arm":
        arms = [a]
    elif case == "dup_names":
        kw["names"] = ["x", "x"]
    elif case == "bad_name":
        kw["names"] = ["x", "../y"]
    elif case == "unknown_baseline":
        kw["baseline"] = "zzz"
    elif case == "no_shared":
        arms = [a, make_image_arm(tmp_path / "c", ["/other/q.jpg"], seed=3)]
    elif case == "mixed":
        arms = [a, make_clip(tmp_path / "clip", "/clips/x.mp4", seed=3)]
    elif case == "not_an_arm":
        (tmp_path / "empty").mkdir()
        arms = [a, tmp_path / "empty"]
    elif case == "bad_design":
        kw["design"] = "tournament"
    with pytest.raises(StudyError):
        build_study(arms, tmp_path / "s", **kw)


@pytest.mark.parametrize("layout", ["records", "annotations", "clip"])
@pytest.mark.parametrize("name", ["../outside.jpg", "images/../../outside.jpg", "absolute"])
def test_a_file_name_outside_its_arm_is_refused(tmp_path, layout, name):
    """A record whose ``file_name`` leads out of its arm's folder (``..``, an absolute path) would put a file that
    is no output of the arm into the study: the build refuses it, naming the record, and copies nothing."""
    (tmp_path / "arms").mkdir()
    outside = tmp_path / "arms" / "outside.jpg"  # beside the arms' folders
    outside.write_bytes(b"\xff\xd8 not an output of the arm")
    if name == "absolute":
        name = str(outside)
    if layout == "clip":
        a = make_clip(tmp_path / "arms" / "a", "/clips/x.mp4", seed=1)
        b = make_clip(tmp_path / "arms" / "b", "/clips/x.mp4", seed=2)
        ann = json.loads((b / "annotations.json").read_text())
        ann["images"][0]["file_name"] = name.replace("images/", "frames/")
        (b / "annotations.json").write_text(json.dumps(ann))
        where = "annotations.json image 1"
    else:
        a = make_image_arm(tmp_path / "arms" / "a", SOURCES, seed=1)
        b = make_image_arm(tmp_path / "arms" / "b", SOURCES, seed=2)
        if layout == "records":
            rec = json.loads((b / "records" / "000000.json").read_text())
            rec["file_name"] = name
            (b / "records" / "000000.json").write_text(json.dumps(rec))
            where = "000000.json"
        else:
            shutil.rmtree(b / "records")
            ann = json.loads((b / "annotations.json").read_text())
            ann["images"][0]["file_name"] = name
            (b / "annotations.json").write_text(json.dumps(ann))
            where = "annotations.json image 1"
    with pytest.raises(StudyError, match=re.escape(where) + ".*outside the arm"):
        build_study([a, b], tmp_path / "s")
    assert not (tmp_path / "s" / "study.json").exists()


def test_rebuild_needs_force_and_never_over_votes(tmp_path):
    arms = image_arms(tmp_path, 2)
    build_study(arms, tmp_path / "s")
    with pytest.raises(StudyError, match="--force"):
        build_study(arms, tmp_path / "s")
    build_study(arms, tmp_path / "s", force=True, seed=5)
    (tmp_path / "s" / "votes.sqlite").write_bytes(b"")
    with pytest.raises(StudyError, match="votes"):
        build_study(arms, tmp_path / "s", force=True)


def test_media_path_stays_inside_media(tmp_path):
    build_study(image_arms(tmp_path, 2), tmp_path / "s")
    s = load_study(tmp_path / "s")
    pid = next(iter(s.pairs))
    assert s.media_path(pid, "L", 0).parent == (tmp_path / "s" / "media").resolve()
    assert s.media_path(pid, "L", 1) is None and s.media_path(pid, "X", 0) is None
    assert s.media_path("000000000000", "L", 0) is None
    s.pairs[pid]["left"] = ["media/../key.json"]  # a tampered study.json cannot point outside media/
    assert s.media_path(pid, "L", 0) is None


def test_load_study_errors(tmp_path):
    with pytest.raises(StudyError, match="study.json"):
        load_study(tmp_path)
    build_study(image_arms(tmp_path, 2), tmp_path / "s")
    (tmp_path / "s" / "key.json").unlink()
    with pytest.raises(StudyError, match="key.json"):
        load_study(tmp_path / "s")
