"""A clip's output folder, through the image command's manifest machinery (:mod:`aias_augment.cli.manifest`).

The run key is :func:`~aias_augment.cli.manifest.run_key`'s (version, seed, preset, config hash, options, input
paths) with ``kind: "clip"`` and the inputs' content hashes in the options, so another seed, option or input
content is another run: refused unless ``overwrite``, which removes only the files the old manifest lists.
The manifest lists every file the clip writes before the first is written (``complete: false``) and turns
complete after the last; each file goes through a temporary file and a rename
(:func:`~aias_augment.cli.manifest.write_file`, which also holds the ``AIAS_TEST_KILL_AFTER_WRITES`` test hook).
A clip is *already done* only when the manifest matches, says complete, and every file it lists is there.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aias_augment.cli.manifest import (
    build_manifest,
    file_hash,
    mark_complete,
    prepare_output,
    read_manifest,
    run_key,
    write_file,
)

MANIFEST = "manifest.json"


@dataclass(frozen=True)
class ClipInput:
    """One input file or frame folder of a clip: ``role`` the option that named it."""

    role: str
    path: str
    sha256: str


def files_hash(paths: list[Path]) -> str:
    """One sha256 over the names and contents of ``paths`` (a frame folder's used frames)."""
    h = hashlib.sha256()
    for p in paths:
        h.update(f"{p.name}\0{file_hash(p)}\0".encode())
    return h.hexdigest()


def clip_manifest(cfg, seed: int, preset: str, options: dict, inputs: list[ClipInput], files: list[str]) -> dict:
    """The manifest of a clip run: ``cfg`` a dataclass of its settings (hashed), ``files`` what it writes."""
    options = {**options, "kind": "clip", "inputs": {i.role: i.sha256 for i in inputs}}
    return build_manifest(
        inputs, cfg, seed, preset, options, hashes=[i.sha256 for i in inputs], outputs=[*sorted(files), MANIFEST]
    )


class ClipOutput:
    """The output folder of one clip run; use it inside :func:`~aias_augment.cli.manifest.output_lock`."""

    def __init__(self, out: Path, manifest: dict):
        self.out, self.manifest = Path(out), manifest
        self.written: set[str] = set()

    def done(self) -> bool:
        """This run is in the folder, complete, with every file it lists."""
        old = read_manifest(self.out)
        return (
            old is not None
            and old.get("complete") is True
            and run_key(old) == run_key(self.manifest)
            and all((self.out / rel).is_file() for rel in self.manifest["outputs"])
        )

    def begin(self, overwrite: bool = False) -> None:
        """Check the folder against this run and record it (:func:`~aias_augment.cli.manifest.prepare_output`)."""
        prepare_output(self.out, self.manifest, overwrite)

    def complete(self) -> None:
        missing = sorted(set(self.manifest["outputs"]) - self.written - {MANIFEST})
        if missing:
            raise RuntimeError(f"clip output incomplete, not written: {missing}")
        mark_complete(self.out, self.manifest)

    def write_with(self, name: str, write: Callable[[Path], object]) -> None:
        """``write(temp_path)`` makes the file ``name``, which is then renamed into place."""
        if name not in self.manifest["outputs"] or name == MANIFEST:
            raise ValueError(f"{name} is not an output of this run's manifest")
        write_file(self.out / name, self.manifest["temp_prefix"], write)
        self.written.add(name)

    def write_bytes(self, name: str, data: bytes, check: Callable[[Path], object] | None = None) -> None:
        """``data`` into ``name``; ``check(temp_path)`` may refuse it before it is in place."""

        def put(tmp: Path) -> None:
            with open(tmp, "xb") as f:
                f.write(data)
            if check is not None:
                check(tmp)

        self.write_with(name, put)

    def write_json(self, name: str, obj, check: Callable[[Path], object] | None = None) -> None:
        self.write_bytes(name, json.dumps(obj).encode(), check)

    def write_image(self, name: str, rgb: np.ndarray) -> None:
        ok, buf = cv2.imencode(Path(name).suffix, np.ascontiguousarray(rgb[..., ::-1]))
        if not ok:
            raise OSError(f"cannot encode {name}")
        self.write_bytes(name, buf.tobytes())
