"""Fuzzing every command line with bad values (issue 54): each run ends with a result (exit 0 or 1) or one stderr
line and exit 2, never a traceback, and writes nothing but its outputs.

The arguments are drawn from each parser's own options (read from the argparse parser the command builds), on top
of a small command that would run on a sandbox of tiny inputs (one 64x48 image, a YOLO folder of it, a 2-frame
clip), with values from a pool of bad ones: negative, zero, huge, NaN/inf, empty, undecodable text, a missing path,
a path through a file, the output folder equal to an input. Every example runs in a fresh sandbox as the working
directory; the sandbox is hashed before and after: no file that was there may change (unless the command line
names it as an output and as nothing else), and every new file lies inside an output the command line names.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import importlib
import io
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path
from unittest import mock

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

REPO = Path(__file__).resolve().parents[3]
ENTRY = {
    "aias-augment": "aias_augment.cli.augment:main",
    "aias-assets": "aias_augment.cli.assets:main",
    "aias-scenes": "aias_augment.cli.scenes:main",
    "aias-abstudy": "aias_augment.evaluation.abstudy.cli:main",
    "aias-study": "detection_eval.study.cli:main",
    "detection-eval": "detection_eval.cli:main",
}
#: The small command each fuzzed command line starts from ({S}: the sandbox, {O}: a fresh output path in it).
BASE = {
    ("aias-augment", "images"): ["--images", "{S}/in", "--preset", "fast", "--out", "{O}"],
    ("aias-augment", "yolo"): ["--yolo", "{S}/yolo/images", "--preset", "fast", "--out", "{O}"],
    ("aias-augment", "clip"): ["--input", "{S}/clip", "--camera", "{S}/cam.yaml", "--poses", "{S}/poses.txt"]
    + ["--out", "{O}"],
    ("aias-assets", "list"): ["list", "--category", "traffic_cone"],
    ("aias-assets", "from-labels"): ["from-labels", "--yolo", "{S}/yolo/images", "--class-names", "cone"]
    + ["--category", "traffic_cone", "--out", "{O}"],
    ("aias-assets", "box-convention"): ["box-convention", "--yolo", "{S}/yolo/images", "--class-names", "cone"]
    + ["--label", "cone", "--out", "{O}/convention.json"],
    ("aias-assets", "deform"): ["deform", "--category", "traffic_cone", "--count", "1", "--seed", "0"]
    + ["--out", "{O}"],
    ("aias-assets", "reconstruct"): ["reconstruct", "--views", "{S}/views.json", "--category", "traffic_cone"]
    + ["--out", "{O}"],
    ("aias-scenes", "index"): ["index", "{S}/in", "--out", "{O}/index.npz", "--words", "8"],
    ("aias-scenes", "query"): ["query", "--index", "{S}/file.txt", "--image", "{S}/in/a.png"],
    ("aias-scenes", "name"): ["name", "--index", "{S}/file.txt", "--name", "road", "--image", "{S}/in/a.png"]
    + ["--region", "0", "0", "8", "8"],
    ("aias-abstudy", "build"): ["build", "--arms", "{S}/in", "{S}/empty", "--out", "{O}"],
    ("aias-abstudy", "serve"): ["serve", "{S}/empty", "--port", "0"],
    ("aias-abstudy", "report"): ["report", "{S}/empty"],
    ("aias-study", ""): ["--config", "{S}/bad.yaml", "--stage", "summarize"],
    ("detection-eval", "eval"): ["eval", "--weights", "{S}/file.txt", "--data", "{S}/yolo"]
    + ["--out", "{O}/metrics.json"],
    ("detection-eval", "train"): ["train", "--data", "{S}/yolo", "--names", "cone", "--iters", "1", "--out", "{O}"],
    ("detection-eval", "predict"): ["predict", "--weights", "{S}/file.txt", "--images", "{S}/in", "--out", "{O}"],
}
#: Options whose value is where a command writes (a file or a folder): new files may appear there only.
OUTPUT_OPTIONS = {"--out", "--csv", "--votes-csv", "--sheet", "--report", "--scene-cache"}
#: Options not fuzzed: they choose a machine, not a value (--backend ray starts a cluster; --address names one).
NOT_FUZZED = {"-h", "--help", "--address", "--workers", "--host"}
BAD_VALUES = [
    "-1",
    "0",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "",
    " ",
    "9" * 30,
    "1.5",
    "\udcff\udcfe",  # bytes that are not UTF-8, as Python hands them over from argv
    "é☃\u202e",
    "{S}/missing",
    "{S}/file.txt",
    "{S}/file.txt/sub",
    "{S}/in",
    "{S}/in/a.png",
    "{S}",
    "{O}",
    "{S}/bad.yaml",
    "{S}/bad.json",
    "{S}/empty",
    "{S}/yolo",
    "{S}/yolo/labels/a.txt",
]
#: Base command lines kept whole: without their bounds they are valid long runs (training to the config's end).
WHOLE = {("detection-eval", "train")}
EXAMPLE_SECONDS = 120  # a bad value that starts unbounded work fails the example instead of hanging the suite
LOG_LINE = re.compile(r"^(\S+ \S+ )?(DEBUG|INFO|WARNING) ")  # a log record (aias-study puts the time first)


def make_sandbox(root: Path) -> None:
    """Tiny inputs every base command reads: an image folder, a YOLO set of it, a 3-frame clip with a camera and
    poses, a text file, a bad YAML and JSON, an empty folder and a views file."""
    rng = np.random.default_rng(0)
    img = (rng.random((48, 64, 3)) * 255).astype(np.uint8)
    (root / "in").mkdir()
    cv2.imwrite(str(root / "in" / "a.png"), img)
    for d in ("yolo/images", "yolo/labels", "clip", "empty"):
        (root / d).mkdir(parents=True)
    cv2.imwrite(str(root / "yolo" / "images" / "a.png"), img)
    (root / "yolo" / "labels" / "a.txt").write_text("0 0.5 0.5 0.5 0.6\n")
    for i in range(3):
        cv2.imwrite(str(root / "clip" / f"{i:06d}.png"), img)
    (root / "cam.yaml").write_text("fx: 60\nfy: 60\ncx: 32\ncy: 24\n")
    (root / "poses.txt").write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {4.0 * i}\n" for i in range(3)))
    (root / "file.txt").write_text("just text\n")
    (root / "bad.yaml").write_text("a: [1, 2\n")
    (root / "bad.json").write_text('{"views": NaN')
    (root / "views.json").write_text(json.dumps({"views": []}))


def tree(root: Path) -> dict[str, str]:
    """{relative path: sha256 of its bytes, or 'folder'} of everything under ``root`` (links not followed)."""
    out = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        if p.is_symlink() or not p.is_file():
            out[rel] = "folder" if p.is_dir() else "other"
        else:
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


_PARSERS: dict[str, argparse.ArgumentParser] = {}


class _Parsed(Exception):
    def __init__(self, parser):
        self.parser = parser


def parser_of(cli: str) -> argparse.ArgumentParser:
    """The argparse parser ``cli``'s ``main`` builds, taken at its ``parse_args`` call (nothing runs)."""
    if cli not in _PARSERS:

        def grab(self, *args, **kwargs):
            raise _Parsed(self)

        module, func = ENTRY[cli].split(":")
        with mock.patch.object(argparse.ArgumentParser, "parse_args", grab), pytest.raises(_Parsed) as got:
            getattr(importlib.import_module(module), func)(["--help"])
        _PARSERS[cli] = got.value.parser
    return _PARSERS[cli]


def options_of(cli: str, sub: str) -> list[argparse.Action]:
    """The fuzzable optional arguments of ``cli`` (and of its subcommand ``sub``)."""
    top = parser_of(cli)
    actions = [a for a in top._actions if not isinstance(a, argparse._SubParsersAction)]
    for a in top._actions:
        if isinstance(a, argparse._SubParsersAction) and sub in a.choices:
            actions += a.choices[sub]._actions
    return [a for a in actions if a.option_strings and not set(a.option_strings) & NOT_FUZZED]


def value_strategy(action: argparse.Action):
    pool = st.sampled_from(BAD_VALUES) | st.text(max_size=8)
    return st.sampled_from(sorted(map(str, action.choices))) | pool if action.choices else pool


@st.composite
def argv_for(draw, cli: str, sub: str) -> list[str]:
    """``BASE[cli, sub]`` with up to three of its parser's options added (or given again) with drawn values, and
    perhaps one base token dropped."""
    argv = list(BASE[cli, sub])
    if (cli, sub) not in WHOLE and draw(st.integers(0, 4)) == 0:
        del argv[draw(st.integers(0, len(argv) - 1))]
    for action in draw(st.lists(st.sampled_from(options_of(cli, sub)), max_size=3)):
        argv.append(draw(st.sampled_from(action.option_strings)))
        if action.nargs == 0:
            continue
        n = {None: 1, "?": draw(st.integers(0, 1)), "*": draw(st.integers(0, 2)), "+": draw(st.integers(1, 2))}
        for _ in range(n.get(action.nargs, action.nargs if isinstance(action.nargs, int) else 1)):
            argv.append(draw(value_strategy(action)))
    return argv


class _TookTooLong(Exception):
    pass


def run_in_process(cli: str, argv: list[str]) -> tuple[int, str]:
    """(exit code, stderr) of ``cli``'s ``main(argv)``; an exception other than SystemExit fails with its
    traceback; a run past :data:`EXAMPLE_SECONDS` fails as unbounded."""
    module, func = ENTRY[cli].split(":")
    main = getattr(importlib.import_module(module), func)
    err, out = io.StringIO(), io.StringIO()

    def alarm(signum, frame):
        raise _TookTooLong(f"{cli} {argv} ran past {EXAMPLE_SECONDS} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(EXAMPLE_SECONDS)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            try:
                code = main(argv)
            except SystemExit as e:
                code = e.code
                if isinstance(code, str):  # Python prints it and exits 1
                    print(code, file=sys.stderr)
                    code = 1
    except _TookTooLong:
        raise
    except BaseException:  # noqa: BLE001 (the property: nothing but SystemExit leaves main)
        pytest.fail(f"{cli} {argv}: traceback\n{traceback.format_exc()}")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        import logging

        logging.basicConfig(stream=sys.__stderr__, force=True)  # the handler must not hold the closed buffer
    return int(code or 0), err.getvalue()


def outputs_of(argv: list[str]) -> list[Path]:
    return [Path(argv[i + 1]) for i, a in enumerate(argv[:-1]) if a in OUTPUT_OPTIONS]


def inside(p: Path, folder: Path) -> bool:
    return p == folder or folder in p.parents


def check_result(cli: str, argv: list[str], code: int, err: str, sandbox: Path, before: dict[str, str]) -> None:
    """The property: exit 0/1 (a result), or 2 with one error line; no traceback; nothing written but outputs."""
    assert code in (0, 1, 2), (cli, argv, code, err)
    assert "Traceback" not in err, (cli, argv, err)
    if code == 2:
        lines = [x for x in err.splitlines() if x.strip() and not LOG_LINE.match(x)]
        assert len(lines) == 1, (cli, argv, err)
    after = tree(sandbox)
    outputs = [(sandbox / o).resolve() if not o.is_absolute() else o for o in outputs_of(argv)]
    inputs = [Path(a) for a in argv if a.startswith(str(sandbox)) and Path(a) not in outputs]
    for rel, digest in before.items():
        p = sandbox / rel
        named_output = any(p == o for o in outputs) and not any(inside(p, i) or inside(i, p) for i in inputs)
        assert after.get(rel) == digest or named_output, (cli, argv, rel, "changed or removed", err)
    for rel in after.keys() - before.keys():
        p = sandbox / rel
        made_for = any(inside(p, o) or (after[rel] == "folder" and inside(o, p)) for o in outputs)  # or its parent
        assert made_for, (cli, argv, rel, "written outside the outputs", err)


def fill(argv: list[str], sandbox: Path) -> list[str]:
    return [a.replace("{S}", str(sandbox)).replace("{O}", str(sandbox / "out")) for a in argv]


def fuzz_once(cli: str, argv: list[str]) -> None:
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        sandbox = Path(tmp).resolve()
        make_sandbox(sandbox)
        argv = fill(argv, sandbox)
        before = tree(sandbox)
        os.chdir(sandbox)
        try:
            code, err = run_in_process(cli, argv)
        finally:
            os.chdir(cwd)
        check_result(cli, argv, code, err, sandbox, before)


PER_BASE = 10  # examples per base command line


def fuzz(cli: str, per_base: int = PER_BASE):
    """A hypothesis test of ``cli``: ``per_base`` examples for each of its base command lines."""
    subs = sorted(s for c, s in BASE if c == cli)
    return settings(
        max_examples=per_base * len(subs),
        deadline=None,
        suppress_health_check=list(HealthCheck),
        derandomize=True,
        database=None,
    ), given(argv=st.sampled_from(subs).flatmap(lambda sub: argv_for(cli, sub)))


def fuzzed(cli: str, per_base: int = PER_BASE):
    limits, drawn = fuzz(cli, per_base)
    return lambda test: limits(drawn(test))


@fuzzed("aias-augment")
def test_aias_augment(argv):
    fuzz_once("aias-augment", argv)


@fuzzed("aias-assets")
def test_aias_assets(argv):
    fuzz_once("aias-assets", argv)


@fuzzed("aias-scenes")
@example(argv=["query", "--index", "{S}/file.txt", "--image", "{S}/in/a.png"])  # np.load's pickle ValueError
def test_aias_scenes(argv):
    fuzz_once("aias-scenes", argv)


@fuzzed("aias-abstudy")
def test_aias_abstudy(argv):
    fuzz_once("aias-abstudy", argv)


@fuzzed("aias-study")
@example(argv=["--config", "{S}/bad.yaml", "--stage", "summarize"])  # ConfigFileError's traceback
def test_aias_study(argv):
    fuzz_once("aias-study", argv)


@fuzzed("detection-eval", per_base=6)  # a valid train is seconds
@example(argv=["eval", "--weights", "{S}/file.txt", "--data", "{S}/yolo"])  # torch.load's KeyError
@example(argv=["train", "--data", "{S}/yolo", "--iters", "0", "--out", "{O}"])  # 0: trained to the config's end
def test_detection_eval(argv):
    fuzz_once("detection-eval", argv)


def run_console_script(cli: str, argv: list[str], sandbox: Path) -> tuple[int, str]:
    env = {**os.environ, "PYTHONIOENCODING": "", "PYTHONUTF8": "0", "LC_ALL": "C.UTF-8"}
    exe = Path(sys.executable).parent / cli
    args = [os.fsencode(a) for a in [str(exe), *argv]]
    r = subprocess.run(args, cwd=sandbox, env=env, capture_output=True, timeout=EXAMPLE_SECONDS)
    return r.returncode, r.stderr.decode("utf-8", "replace")


#: A few command lines per console script, run as a user runs them: exit codes and output encodings as installed.
SMOKE = [
    ("aias-augment", ["--images", "{S}/in", "--out", "{S}/in", "--per-image", "nan"]),
    ("aias-augment", ["--input", "{S}/clip", "--camera", "{S}/cam.yaml", "--poses", "{S}/bad.json", "--out", "{O}"]),
    ("aias-augment", ["--images", "{S}/\udcff", "--out", "{O}"]),
    ("aias-assets", ["deform", "--category", "traffic_cone", "--seed", "-1", "--out", "{O}"]),
    ("aias-scenes", ["query", "--index", "{S}/file.txt", "--image", "{S}/missing"]),
    ("aias-abstudy", ["report", "{S}/file.txt/sub"]),
    ("aias-study", ["--config", "{S}/bad.yaml"]),
    ("detection-eval", ["--weights", "{S}/file.txt", "--data", "{S}/yolo"]),
]


@pytest.mark.parametrize("cli, argv", SMOKE, ids=[f"{c}-{i}" for i, (c, _) in enumerate(SMOKE)])
def test_console_scripts_give_a_result_or_one_line(cli, argv, tmp_path):
    sandbox = tmp_path.resolve()
    make_sandbox(sandbox)
    argv = fill(argv, sandbox)
    before = tree(sandbox)
    code, err = run_console_script(cli, argv, sandbox)
    check_result(cli, argv, code, err, sandbox, before)
