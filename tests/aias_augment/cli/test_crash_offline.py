"""Crash consistency of the offline image writer: ``aias-augment`` killed with SIGKILL at every write step.

Each run is a process forked from a warm parent (imports done, no renderer: each child makes its own EGL context),
so that 25+ kills and their reruns take one to two minutes. The hook ``AIAS_TEST_KILL_AFTER_WRITES=k`` makes the
writer SIGKILL its own process at its k-th write step (a temporary file written, or a rename done), so the kill
points are every step of a run over two images, in order (20 steps; more where the output format writes more
files), and for every 4th of them a second kill in the rerun. After each kill the folder claims nothing it does not
hold: a manifest that says ``complete`` stands beside the whole clean folder, an ``annotations.json`` there is the
whole dataset. A rerun of the same command then gives the clean run's folder: the same files, byte for byte, except
the fields that hold times or the process (:data:`TIME_FIELDS`, the lock file's holder line) and the folder's own
path where a file names it (YOLO's ``data.yaml`` ``path``).
"""

import hashlib
import json
import signal
import subprocess
import sys

import cv2
import pytest

from aias_augment.assets.asset import DEFAULT_ASSETS
from aias_augment.cli.manifest import KILL_HOOK, LOCK_NAME, TEMP_TAG
from aias_augment.core.config import data_root
from tests.aias_augment.pipeline.test_image import road_frame

pytestmark = pytest.mark.skipif(
    not (data_root() / DEFAULT_ASSETS["traffic_cone"][0]).exists(), reason="shared data not present"
)

TIME_FIELDS = {"records/*.json": "seconds", "summary.json": "median_seconds_per_image"}

# A parent that imports the package once and forks one child per run: the child sets the kill hook, silences its
# output and runs ``aias-augment``'s main; the parent answers with how the child ended.
FORK_SERVER = r"""
import json, os, sys
import aias_augment.cli.augment as augment
import aias_augment.cli.offline, aias_augment.pipeline.bounded
from aias_augment.adapters.boundary import known_categories
known_categories()
print("ready", flush=True)
for line in sys.stdin:
    job = json.loads(line)
    pid = os.fork()
    if pid == 0:
        os.environ.pop(job["hook"], None)
        if job["kill_after"]:
            os.environ[job["hook"]] = str(job["kill_after"])
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        os._exit(augment.main(job["argv"]))
    _, status = os.waitpid(pid, 0)
    end = {"signal": os.WTERMSIG(status)} if os.WIFSIGNALED(status) else {"code": os.WEXITSTATUS(status)}
    print(json.dumps(end), flush=True)
"""


class Runner:
    def __init__(self):
        self.proc = subprocess.Popen(
            [sys.executable, "-c", FORK_SERVER], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        assert self.proc.stdout.readline().strip() == "ready"

    def run(self, argv: list[str], kill_after: int | None = None) -> dict:
        self.proc.stdin.write(json.dumps({"argv": argv, "kill_after": kill_after, "hook": KILL_HOOK}) + "\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self):
        self.proc.stdin.close()
        self.proc.wait(timeout=30)


def tree(root) -> dict[str, bytes]:
    """Every file under ``root`` by relative path: its bytes, with the fields that hold times removed and ``root``
    itself written ``<out>``."""
    out = {}
    for p in sorted(root.rglob("*")):
        if not p.is_file():
            continue
        rel = p.relative_to(root).as_posix()
        data = p.read_bytes().replace(str(root).encode(), b"<out>")
        if rel == LOCK_NAME:  # the holder's pid and host
            data = b""
        for pattern, field in TIME_FIELDS.items():
            if p.relative_to(root).match(pattern):
                obj = json.loads(data)
                obj.pop(field)
                data = json.dumps(obj, sort_keys=True).encode()
        out[rel] = data
    return out


def digest(root) -> dict[str, str]:
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in root.rglob("*")
        if p.is_file()
    }


def claims(out, clean: dict[str, bytes]) -> list[str]:
    """What the folder of a killed run claims and does not hold: a manifest that says complete beside another
    folder than the clean run's, or a dataset file that is not the whole one."""
    wrong = []
    manifest = out / "manifest.json"
    if manifest.exists() and json.loads(manifest.read_text()).get("complete") and tree(out) != clean:
        wrong.append("manifest says complete, the folder is not the clean run's")
    ann = out / "annotations.json"
    if ann.exists() and ann.read_bytes() != clean["annotations.json"]:
        wrong.append("annotations.json is not the whole dataset")
    return wrong


def test_kill_at_every_write_step_then_rerun_gives_the_clean_folder(tmp_path):
    data = tmp_path / "data"
    (data / "images").mkdir(parents=True)
    (data / "labels").mkdir()
    for i in range(2):
        img = road_frame()[::4, ::4].copy()
        img[i : i + 5, :] = 40 * i  # two scenes
        cv2.imwrite(str(data / "images" / f"im{i}.png"), img[..., ::-1])
        (data / "labels" / f"im{i}.txt").write_text("0 0.5 0.8 0.1 0.1\n")
    inputs = digest(data)
    args = ["--yolo", str(data / "images"), "--class-names", "sign", "--preset", "fast", "--per-image", "1"]
    args += ["--seed", "5", "--scene-cache", str(tmp_path / "scenes")]
    runner = Runner()
    try:
        assert runner.run([*args, "--out", str(tmp_path / "clean")]) == {"code": 0}
        clean = tree(tmp_path / "clean")
        assert json.loads(clean["manifest.json"])["complete"] is True
        kill_points, k = [], 0
        while True:
            k += 1
            out = tmp_path / f"k{k}"
            end = runner.run([*args, "--out", str(out)], kill_after=k)
            if end == {"code": 0}:  # k is past the last write step: the run finished
                break
            assert end == {"signal": signal.SIGKILL}, (k, end)
            kill_points.append(("run", k))
            assert not claims(out, clean), (k, claims(out, clean))
            if k % 4 == 0:  # a second kill, while the rerun recovers from the first
                assert runner.run([*args, "--out", str(out)], kill_after=3) == {"signal": signal.SIGKILL}, k
                kill_points.append(("resume", k))
                assert not claims(out, clean), (k, claims(out, clean))
            assert runner.run([*args, "--out", str(out)]) == {"code": 0}, k
            got = tree(out)
            assert sorted(got) == sorted(clean), (k, sorted(set(got) ^ set(clean)))
            assert [n for n in clean if got[n] != clean[n]] == [], k
            assert not [n for n in got if TEMP_TAG in n], k
        assert len(kill_points) >= 20, kill_points  # 20 steps of a run over two images, 5 in its resumes
    finally:
        runner.close()
    assert digest(data) == inputs
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["data", "scenes", "clean", *(f"k{k}" for k in range(1, k + 1))]
    )
