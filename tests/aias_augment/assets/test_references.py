"""A glTF / GLB reads nothing outside its folder (issue 54, item 7): tiny one-triangle files written here."""

import json
import struct

import numpy as np
import pytest

from aias_augment.assets.asset import AssetError, load_asset, load_mesh_file
from aias_augment.assets.bank.meshio import load_raw_parts

POSITIONS = np.array([[0, 0, 0], [0.3, 0, 0], [0, 0.5, 0]], np.float32)
BUFFER = POSITIONS.tobytes() + np.array([0, 1, 2], np.uint16).tobytes() + b"\0\0"


def gltf_doc(buffer_uri: str | None, image_uri: str | None = None) -> dict:
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": 3,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [0.3, 0.5, 0],
            },
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6},
        ],
        "buffers": [{"byteLength": len(BUFFER), **({} if buffer_uri is None else {"uri": buffer_uri})}],
    }
    if image_uri is not None:
        doc["images"] = [{"uri": image_uri}]
    return doc


def write_glb(path, doc: dict, binary: bytes = BUFFER) -> None:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    chunks = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(binary), b"BIN\0") + binary
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)


def test_a_buffer_beside_the_gltf_loads(tmp_path):
    (tmp_path / "tri.bin").write_bytes(BUFFER)
    (tmp_path / "tri.gltf").write_text(json.dumps(gltf_doc("tri.bin")))
    meshes = load_mesh_file(tmp_path / "tri.gltf", scale=1.0)
    assert len(meshes) == 1 and len(meshes[0].faces) == 1
    assert np.ptp(np.asarray(meshes[0].vertices), axis=0).max() == pytest.approx(0.5, abs=1e-6)
    write_glb(tmp_path / "tri.glb", gltf_doc(None))
    assert len(load_mesh_file(tmp_path / "tri.glb", scale=1.0)[0].faces) == 1


@pytest.mark.parametrize(
    "uri",
    [
        "../../../../etc/passwd",
        "/etc/passwd",
        "..%2F..%2F..%2F..%2Fetc%2Fpasswd",
        "file:///etc/passwd",
        "sub/../../x.bin",
    ],
)
def test_a_buffer_uri_outside_the_folder_is_refused(tmp_path, uri):
    folder = tmp_path / "a" / "b"
    folder.mkdir(parents=True)
    (tmp_path / "a" / "x.bin").write_bytes(BUFFER)  # exists, but outside the asset's folder
    gltf = folder / "tri.gltf"
    gltf.write_text(json.dumps(gltf_doc(uri)))
    for load in (
        lambda: load_mesh_file(gltf, scale=1.0),
        lambda: load_asset(gltf, category="rock"),
        lambda: load_raw_parts(gltf),
    ):
        with pytest.raises(AssetError, match="outside the asset's folder") as e:
            load()
        assert str(gltf) in str(e.value) and repr(uri) in str(e.value)


def test_a_glb_image_uri_outside_the_folder_is_refused(tmp_path):
    glb = tmp_path / "tri.glb"
    write_glb(glb, gltf_doc(None, image_uri="../secret.png"))
    with pytest.raises(AssetError, match=r"images\[0\] refers to '../secret.png'"):
        load_mesh_file(glb, scale=1.0)
