import cv2
import numpy as np
import pytest

from aias_augment.scenes.retrieval.index import QueryConfig, SceneIndex


def _perturb(img):
    h, w = img.shape[:2]
    c = img[h // 8 : h - h // 8, w // 6 : w - w // 10]
    c = cv2.resize(c, None, fx=0.8, fy=0.8, interpolation=cv2.INTER_AREA)
    return np.clip(c.astype(np.float32) * 1.2 - 15, 0, 255).astype(np.uint8)


def test_perturbed_frames_retrieve_their_source(small_index, frames):
    for d, (ref, img) in enumerate(frames):
        hits = small_index.query_image(_perturb(img), QueryConfig(top_k=3))
        assert hits[0].ref == ref, (ref, hits)
        assert hits[0].inliers >= QueryConfig().min_inliers


def test_inverted_file_equals_dense_cosine(small_index, frames):
    from aias_augment.scenes.retrieval.features import extract_features

    f = extract_features(_perturb(frames[2][1]), small_index.feature_cfg)
    words = small_index.vocab.assign(f.desc)
    dense = small_index.counts.toarray() * small_index.idf
    dense /= np.linalg.norm(dense, axis=1, keepdims=True)
    q = np.bincount(words, minlength=small_index.vocab.size) * small_index.idf
    q /= np.linalg.norm(q)
    np.testing.assert_allclose(small_index.score_tfidf(words), dense @ q, atol=1e-5)


def test_query_by_region(small_index, frames):
    ref, img = frames[5]
    h, w = img.shape[:2]
    hits = small_index.query_image(img, QueryConfig(top_k=1), region_xywh=(w // 4, h // 4, w // 2, h // 2))
    assert hits[0].ref == ref
    with pytest.raises(ValueError, match="outside"):
        small_index.query_image(img, region_xywh=(w + 10, 0, 5, 5))


def test_named_words_find_road_scenes(small_index, frames):
    """'road' learned from the road surface of one KITTI frame ranks the other KITTI street frames above the
    indoor NYU frames and the campus video."""
    ref, img = frames[0]
    h, w = img.shape[:2]
    mask = np.zeros((h, w), bool)
    mask[int(0.72 * h) :, int(0.3 * w) : int(0.7 * w)] = True  # the road in front of the car
    small_index.name_words("road", [(img, mask)], n_words=40)
    frac = small_index.word_fraction(["road"])
    kitti = [d for d, r in enumerate(small_index.refs) if r.clip == "kitti" and r != ref]
    nyu = [d for d, r in enumerate(small_index.refs) if r.clip == "nyu"]
    assert min(frac[kitti]) > max(frac[nyu])
    top = small_index.query_words(["road"], top_k=len(kitti) + 1)
    assert {h.ref.clip for h in top} == {"kitti"}
    with pytest.raises(KeyError, match="unknown word names"):
        small_index.query_words(["sky"])


def test_save_load_round_trip(small_index, frames, tmp_path):
    path = small_index.save(tmp_path / "idx.npz")
    loaded = SceneIndex.load(path)
    assert loaded.refs == small_index.refs and set(loaded.names) == set(small_index.names)
    q = _perturb(frames[1][1])
    a = [(h.ref, h.inliers) for h in small_index.query_image(q)]
    b = [(h.ref, h.inliers) for h in loaded.query_image(q)]
    assert a == b
    with pytest.raises(FileNotFoundError):
        SceneIndex.load(tmp_path / "missing.npz")
