"""Shared pieces of the A/B study tests: arms in the aias-augment output layout, a real server process, raw HTTP."""

from __future__ import annotations

import http.client
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import urlparse

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[4]


def _image(seed: int, w: int = 64, h: int = 48) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 255, (h, w, 3), dtype=np.uint8)


def make_image_arm(
    root: Path,
    sources: list[str],
    seed: int,
    *,
    skipped: tuple[int, ...] = (),
    same_as: Path | None = None,
    same_idx: tuple[int, ...] | None = None,
) -> Path:
    """An ``aias-augment --input/--yolo`` output folder as ``offline.process_item`` writes it: ``images/``,
    ``records/NNNNNN.json`` (``source``, ``file_name``, ...) and ``annotations.json`` (images with ``source``).
    ``same_as``: copy the images of that arm (identical outputs), for the indices ``same_idx`` (default all)."""
    (root / "images").mkdir(parents=True, exist_ok=True)
    (root / "records").mkdir(exist_ok=True)
    images = []
    for i, src in enumerate(sources):
        if i in skipped:
            rec = {"index": i, "source": src, "skipped": "ValueError: cannot read image"}
        else:
            name = f"{i:06d}_{Path(src).stem}.png"
            same = same_as is not None and (same_idx is None or i in same_idx)
            img = cv2.imread(str(same_as / "images" / name)) if same else _image(seed * 1000 + i)
            cv2.imwrite(str(root / "images" / name), img)
            rec = {
                "index": i,
                "source": src,
                "file_name": name,
                "seed": [seed, i],
                "width": 64,
                "height": 48,
                "boxes": [[1.0, 2.0, 10.0, 20.0]],
                "labels": ["traffic_cone"],
                "inserted": [True],
            }
            images.append({"id": len(images) + 1, "file_name": name, "width": 64, "height": 48, "source": src})
        (root / "records" / f"{i:06d}.json").write_text(json.dumps(rec))
    (root / "annotations.json").write_text(json.dumps({"images": images, "annotations": [], "categories": []}))
    return root


def make_clip(root: Path, source: str, seed: int, n_frames: int = 4, fps: float = 10.0) -> Path:
    """An ``aias-augment`` clip output: ``frames/*.jpg``, ``annotations.json``, ``record.json`` with its job."""
    (root / "frames").mkdir(parents=True, exist_ok=True)
    images = []
    for i in range(n_frames):
        name = f"frames/{i:06d}.jpg"
        cv2.imwrite(str(root / name), _image(seed * 1000 + i))
        images.append({"id": i + 1, "file_name": name, "width": 64, "height": 48, "frame_index": i})
    (root / "annotations.json").write_text(json.dumps({"images": images, "annotations": [], "categories": []}))
    job = {
        "input": source,
        "camera": "calib.txt",
        "poses": "poses.txt",
        "out": str(root),
        "start": 0,
        "stride": 1,
        "fps": fps,
        "seed": seed,
    }
    (root / "record.json").write_text(
        json.dumps({"job": job, "frames": n_frames, "frame_indices": list(range(n_frames))})
    )
    return root


SOURCES = [f"/data/roads/img_{i:03d}.jpg" for i in range(5)]


def image_arms(tmp: Path, n_arms: int = 3, sources=SOURCES) -> list[Path]:
    return [
        make_image_arm(tmp / name, list(sources), seed=k + 1)
        for k, name in enumerate(["naive_paste", "full", "no_shadow"][:n_arms])
    ]


# ---------------------------------------------------------------------------------------------------- server
class Server:
    """``aias-abstudy serve STUDY --port 0`` in a real process (uvicorn); ``url`` is read from its first line."""

    def __init__(self, study: Path):
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "aias_augment.evaluation.abstudy.cli", "serve", str(study), "--port", "0"],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=REPO,
            env=env,
        )
        line = self.proc.stdout.readline()
        if " on http://" not in line:
            self.proc.kill()
            raise RuntimeError(f"server did not start: {line}{self.proc.stdout.read()}")
        self.url = line.split(" on ")[1].split()[0].rstrip("/")
        u = urlparse(self.url)
        self.host, self.port = u.hostname, u.port
        deadline = time.monotonic() + 30
        while True:
            try:
                if request(self, "GET", "/healthz")[0] == 200:
                    break
            except OSError:
                if time.monotonic() > deadline or self.proc.poll() is not None:
                    self.stop()
                    raise
                time.sleep(0.05)

    def stop(self, kill: bool = False) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL if kill else signal.SIGTERM)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc.stdout.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


class InProcessServer:
    """An app from ``create_app`` served by uvicorn in a thread of this process, so a test can patch its parts (the
    vote store); ``host`` and ``port`` as :class:`Server`."""

    def __init__(self, app):
        import socket
        import threading

        import uvicorn

        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(16)
        self.host, self.port = self.sock.getsockname()
        self.server = uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False))
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("the in-process server did not start")
            time.sleep(0.01)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.server.should_exit = True
        self.thread.join(15)
        self.sock.close()


def request(
    server: Server,
    method: str,
    path: str,
    body=None,
    headers: dict | None = None,
    raw: bytes | None = None,
    timeout: float = 30.0,
):
    """One HTTP request with the path sent exactly as given (no normalisation of ``..``); returns
    (status, parsed JSON or text, headers)."""
    con = http.client.HTTPConnection(server.host, server.port, timeout=timeout)
    try:
        hdrs = dict(headers or {})
        data = raw
        if body is not None:
            data = json.dumps(body).encode()
            hdrs.setdefault("Content-Type", "application/json")
        con.request(method, path, body=data, headers=hdrs)
        resp = con.getresponse()
        payload = resp.read()
        ctype = resp.getheader("Content-Type", "")
        if "json" in ctype:
            parsed = json.loads(payload) if payload else None
        elif ctype.startswith(("text/", "application/javascript")) or not payload:
            parsed = payload.decode("utf-8", "replace")
        else:
            parsed = payload
        return resp.status, parsed, {k.lower(): v for k, v in resp.getheaders()}
    finally:
        con.close()
