"""The clip door from Python (pipeline.clip_objects.insert_objects_into_clip) on KITTI 06 frames and GT poses:
arrays in, frames and per-object tracks out, no files; the CLI's checks of what to insert are the door's own."""

import numpy as np
import pytest

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.core.config import data_root
from aias_augment.pipeline.clip_objects import ClipRequest, insert_objects_into_clip

SEQ = data_root() / "kitti06_seq"
N = 6


@pytest.fixture(scope="module")
def kitti_clip():
    if not SEQ.exists():
        pytest.skip("shared KITTI data not available")
    from aias_augment.scenes.kitti import open_kitti_sequence

    seq = open_kitti_sequence(SEQ)
    frames = [seq.frame(i).image for i in range(N)]
    poses = np.stack([seq.cam_from_world(i) for i in range(N)])
    return seq.intrinsics, frames, poses


def _insert(kitti_clip, **request):
    intr, frames, poses = kitti_clip
    req = ClipRequest(lighting="ambient", harmonize="none", lookahead_frames=0, ahead_m=10.0, **request)
    return insert_objects_into_clip(frames, intr, poses, prior_ground_plane(1.65), req)


def test_door_inserts_two_tracks_from_arrays_and_leaves_the_inputs_alone(kitti_clip):
    _, frames, _ = kitti_clip
    before = [f.copy() for f in frames]
    clip = _insert(kitti_clip, objects=2, seed=4)
    assert all(np.array_equal(a, b) for a, b in zip(frames, before))  # every input byte unchanged
    assert len(clip.frames) == N and len(clip.results) == len(clip.plans) == len(clip.objects) == 2
    assert clip.skipped_objects == [] and clip.draws[0] == 1
    for r in clip.results:
        assert len(r.boxes_xywh) == N and any(b is not None for b in r.boxes_xywh)
        for b, m in zip(r.boxes_xywh, r.masks):
            assert (b is None) == (m is None or not np.any(m > 0))
    # objects share the world: the two contacts are apart by more than a cone's base
    c1, c2 = (np.asarray(r.contact_in_world) for r in clip.results)
    assert np.linalg.norm(c1 - c2) > 0.5
    drawn = [i for i in range(N) if any(r.boxes_xywh[i] is not None for r in clip.results)]
    assert all(not np.array_equal(clip.frames[i], frames[i]) for i in drawn)


def test_grey_clip_stays_grey_and_the_notes_say_so(kitti_clip):
    """KITTI image_l is a grey camera read as RGB: the door returns grey frames, an orange cone would give it away."""
    _, frames, _ = kitti_clip
    assert all(np.array_equal(f[..., 0], f[..., 1]) and np.array_equal(f[..., 1], f[..., 2]) for f in frames)
    clip = _insert(kitti_clip, seed=0)
    assert all(np.array_equal(f[..., 0], f[..., 1]) and np.array_equal(f[..., 1], f[..., 2]) for f in clip.frames)
    assert clip.notes["colour"] == "grey clip: output converted to grey"
    assert clip.notes["camera"] == "given camera and poses"


def test_same_seed_same_bytes_other_seed_other_frames(kitti_clip):
    a, b, c = (_insert(kitti_clip, seed=s) for s in (7, 7, 8))
    assert all(np.array_equal(x, y) for x, y in zip(a.frames, b.frames))
    assert not all(np.array_equal(x, y) for x, y in zip(a.frames, c.frames))


@pytest.mark.parametrize(
    "field, value, words",
    [
        ("camera_height_m", 500.0, "camera_height_m (--camera-height) must be in (0, 100] metres"),
        ("objects", 0, "objects must be >= 1, got 0"),
        ("lighting", "sunny", "lighting must be 'clip' or 'ambient'"),
        ("object_start_s", 1.0, "--object-start and --object-accel need --object-speed"),
    ],
)
def test_request_refuses_bad_values_at_construction_as_the_command_does(field, value, words, tmp_path):
    """One set of checks: the door's request refuses a bad value when built, and the CLI's job (which builds that
    request) refuses it with the same words."""
    from aias_augment.cli.clip import ClipJob

    with pytest.raises(ValueError) as door:
        ClipRequest(**{field: value})
    with pytest.raises(ValueError) as job:
        ClipJob("in", "calib.txt", "poses.txt", str(tmp_path), **{field: value})
    assert words in str(door.value) and str(job.value) == str(door.value)
