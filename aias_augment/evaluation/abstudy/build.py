"""Build a study from ``aias-augment`` output folders ("arms") made on the same inputs.

An arm is one of:

- an image run: ``records/NNNNNN.json`` (each with ``source``, the input image, and ``file_name`` under ``images/``),
  as ``aias-augment --input/--yolo`` writes; without ``records/``, ``annotations.json`` images with ``source``;
- a clip run: ``record.json`` (its ``job`` names the input clip, first frame and stride) and ``frames/*.jpg``;
- a folder of clip runs (sub-folders that each hold a ``record.json``).

Arms are matched item by item on their source: the source path (normalised), or, when no path is shared, the
source's file name (if it is unique in both arms). With the default design every other arm is paired with the
baseline on every shared source (``design="all-pairs"``: every two arms). Left and right are balanced within each
comparison (half of the pairs show the baseline on the left, in a seeded random order), the pair order is shuffled,
pair ids are random tokens and media are copied under content hashes, so nothing a rater sees names an arm. The
answer key (which arm is left and right) goes to ``key.json``, which the server never serves.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import logging
import os
import random
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from aias_augment.core.coco_io import atomic_write_json
from aias_augment.core.errors import AiasError

log = logging.getLogger(__name__)

FORMAT = "aias-abstudy/1"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".webp", ".bmp")
MEDIA_TYPES = {
    ".png": "image/png",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
    ".webp": "image/webp",
    ".bmp": "image/bmp",
}
ARM_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}$")
PAIR_ID_RE = re.compile(r"^[0-9a-f]{12}$")
DESIGNS = ("baseline", "all-pairs")


class StudyError(AiasError, ValueError):
    """A study that cannot be built or loaded, with the reason."""


@dataclass(frozen=True)
class Entry:
    """One item of an arm: an image, or the frames of a clip."""

    key: str  # the source it was made from (normalised path; clips: path@start+stride)
    name: str  # the source's file name (fallback match key)
    kind: str  # "image" | "clip"
    files: tuple[Path, ...]  # one image, or the frames in order
    fps: float | None = None


# ------------------------------------------------------------------------------------------------ reading arms
def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise StudyError(f"{path}: cannot read ({e})") from e


def _inside_arm(root: Path, f: Path, where: str, name) -> Path:
    """``f`` if it resolves inside the arm's folder ``root``; a ``file_name`` that leads out of it (``..``, an
    absolute path, a link) would copy a file that is no output of the arm: StudyError naming ``where``."""
    if root.resolve() not in f.resolve().parents:
        raise StudyError(f"{where}: file_name {name!r} is outside the arm's folder {root}")
    return f


def _image_arm(root: Path) -> list[Entry]:
    recs = []
    if (root / "records").is_dir():
        for p in sorted((root / "records").glob("*.json")):
            if ".tmp" in p.name:
                continue
            recs.append((str(p), _read_json(p)))
    elif (root / "annotations.json").is_file():
        recs = [
            (f"{root / 'annotations.json'} image {im.get('id')}", im)
            for im in _read_json(root / "annotations.json").get("images", [])
        ]
    out = []
    for where, rec in recs:
        if "skipped" in rec or "file_name" not in rec or "source" not in rec:
            continue
        f = root / "images" / rec["file_name"]
        if not f.is_file():
            f = root / rec["file_name"]
        _inside_arm(root, f, where, rec["file_name"])
        if not f.is_file() or f.suffix.lower() not in IMAGE_SUFFIXES:
            log.warning("%s: %s listed but missing or not an image, left out", root, rec["file_name"])
            continue
        src = os.path.normpath(str(rec["source"]))
        out.append(Entry(src, Path(src).name, "image", (f,)))
    return out


def _clip_entry(root: Path) -> Entry:
    rec = _read_json(root / "record.json")
    job = rec.get("job") or {}
    if "input" not in job:
        raise StudyError(f"{root}/record.json: no job.input (not an aias-augment clip record)")
    frames = []
    if (root / "annotations.json").is_file():
        ims = _read_json(root / "annotations.json").get("images", [])
        ims = sorted(ims, key=lambda im: (im.get("frame_index", 0), im.get("id", 0)))
        frames = [
            _inside_arm(root, root / im["file_name"], f"{root}/annotations.json image {im.get('id')}", im["file_name"])
            for im in ims
        ]
    if not frames:
        frames = sorted(
            _inside_arm(root, p, f"{root}/frames", p.name)
            for p in (root / "frames").glob("*")
            if p.suffix.lower() in IMAGE_SUFFIXES
        )
    missing = [str(f) for f in frames if not f.is_file()]
    if not frames or missing:
        raise StudyError(f"{root}: clip frames missing ({missing[:3] or 'none found'})")
    src = os.path.normpath(str(job["input"]))
    suffix = f"@{job.get('start', 0)}+{job.get('stride', 1)}"
    return Entry(src + suffix, Path(src).name + suffix, "clip", tuple(frames), float(job.get("fps") or 10.0))


def read_arm(path: str | Path) -> list[Entry]:
    """The items of one arm (see the module docstring for the folder layouts)."""
    root = Path(path)
    if not root.is_dir():
        raise StudyError(f"{root}: not a folder")
    if (root / "record.json").is_file():
        entries = [_clip_entry(root)]
    elif (root / "records").is_dir() or (root / "annotations.json").is_file():
        entries = _image_arm(root)
    else:
        entries = [_clip_entry(d) for d in sorted(root.iterdir()) if (d / "record.json").is_file()]
    if not entries:
        raise StudyError(f"{root}: no aias-augment output found (records/, annotations.json or record.json)")
    keys = [e.key for e in entries]
    if len(set(keys)) != len(keys):
        dup = sorted({k for k in keys if keys.count(k) > 1})
        raise StudyError(f"{root}: the same source appears more than once ({dup[:3]}); one output per source")
    return entries


def orient(arms: list[str], baseline: str, x: str, y: str) -> tuple[str, str]:
    """(method, opponent) of a comparison: against the baseline the other arm is the method; between two other arms,
    the one listed first."""
    if x == baseline or y == baseline:
        return (y, x) if x == baseline else (x, y)
    return (x, y) if arms.index(x) < arms.index(y) else (y, x)


def match_entries(a: list[Entry], b: list[Entry]) -> list[tuple[Entry, Entry]]:
    """Items of ``a`` and ``b`` made from the same source: by path, else by file name if unique in both."""
    kb = {e.key: e for e in b}
    pairs = [(e, kb[e.key]) for e in a if e.key in kb]
    if pairs:
        return pairs

    def unique_names(es):
        names = [e.name for e in es]
        return {e.name: e for e in es if names.count(e.name) == 1}

    na, nb = unique_names(a), unique_names(b)
    return [(na[n], nb[n]) for n in na if n in nb]


# ----------------------------------------------------------------------------------------------------- building
def _sha(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _atomic_json(path: Path, obj) -> None:
    atomic_write_json(path, obj, indent=1)


class _Media:
    """Copies files into ``media/`` under their content hash (deduplicated)."""

    def __init__(self, root: Path):
        self.root = root
        self.dir = root / "media"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.digests: dict[Path, str] = {}

    def digest(self, f: Path) -> str:
        if f not in self.digests:
            self.digests[f] = _sha(f)
        return self.digests[f]

    def add(self, f: Path) -> str:
        name = self.digest(f)[:20] + f.suffix.lower()
        dst = self.dir / name
        if not dst.exists():
            tmp = dst.with_name(dst.name + ".tmp")
            shutil.copyfile(f, tmp)
            os.replace(tmp, dst)
        return f"media/{name}"


def _checked_arms(arms, out: Path, names, baseline, design: str, force: bool) -> tuple[list[str], str]:
    """The arms' names and the baseline of :func:`build_study`, after its arguments and ``out`` are checked
    (StudyError naming what to change)."""
    if len(arms) < 2:
        raise StudyError("a study needs at least two arms")
    names = list(names) if names else [Path(a).resolve().name for a in arms]
    if len(names) != len(arms):
        raise StudyError(f"{len(names)} names for {len(arms)} arms")
    bad = [n for n in names if not ARM_NAME_RE.match(n)]
    if bad:
        raise StudyError(f"arm names must be 1-64 letters, digits or _.+- (got {bad}); use --names")
    if len(set(names)) != len(names):
        raise StudyError(f"arm names must be distinct, got {names}; use --names")
    baseline = baseline or names[0]
    if baseline not in names:
        raise StudyError(f"baseline {baseline!r} is not an arm ({names})")
    if design not in DESIGNS:
        raise StudyError(f"design must be one of {DESIGNS}, got {design!r}")
    if (out / "votes.sqlite").exists():
        raise StudyError(
            f"{out} already has votes (votes.sqlite); a rebuilt key would not match them. "
            "Build into a new folder, or move votes.sqlite away first"
        )
    if (out / "study.json").exists() and not force:
        raise StudyError(f"{out} already holds a study; use --force to rebuild it")
    return names, baseline


def _new_pair_id(rng: random.Random, used_ids: set[str]) -> str:
    """A 12-hex-digit pair id drawn from ``rng``, not in ``used_ids`` (added to it)."""
    while True:
        pid = f"{rng.getrandbits(48):012x}"
        if pid not in used_ids:
            used_ids.add(pid)
            return pid


def _pair_record(pid: str, source: Entry, left: Entry, right: Entry, media: _Media) -> dict:
    """A pair as the study file holds it: its media copied into ``media/`` (left, then right)."""
    return {
        "id": pid,
        "kind": left.kind,
        "source": source.name,
        "fps": left.fps if left.kind == "clip" else None,
        "left": [media.add(f) for f in left.files],
        "right": [media.add(f) for f in right.files],
    }


def build_study(
    arms: list[str | Path],
    out: str | Path,
    *,
    names: list[str] | None = None,
    baseline: str | None = None,
    design: str = "baseline",
    seed: int = 0,
    title: str | None = None,
    force: bool = False,
) -> dict:
    """Write a study to ``out``; returns a summary (pairs per comparison, what was left out and why)."""
    out = Path(out)
    names, baseline = _checked_arms(arms, out, names, baseline, design, force)
    entries = {n: read_arm(a) for n, a in zip(names, arms)}
    kinds = {e.kind for es in entries.values() for e in es}
    if len(kinds) > 1:
        raise StudyError(f"arms mix images and clips ({ {n: es[0].kind for n, es in entries.items()} })")
    rng = random.Random(seed)
    if design == "baseline":
        comparisons = [(baseline, n) for n in names if n != baseline]
    else:
        comparisons = list(itertools.combinations(names, 2))
    if (out / "media").exists() and force:
        shutil.rmtree(out / "media")
    out.mkdir(parents=True, exist_ok=True)
    media = _Media(out)
    pairs, key, summary = [], {}, {"comparisons": {}, "identical_left_out": 0, "unmatched": {}}
    used_ids: set[str] = set()
    for a_name, b_name in comparisons:
        matched = match_entries(entries[a_name], entries[b_name])
        label = "{} vs {}".format(*orient(names, baseline, a_name, b_name))
        summary["unmatched"][label] = len(entries[a_name]) + len(entries[b_name]) - 2 * len(matched)
        kept = []
        for ea, eb in matched:
            if [media.digest(f) for f in ea.files] == [media.digest(f) for f in eb.files]:
                summary["identical_left_out"] += 1  # nothing to choose between
                continue
            kept.append((ea, eb))
        if not kept:
            raise StudyError(
                f"{b_name} and {a_name} share no source with different outputs "
                f"(e.g. {entries[a_name][0].key} vs {entries[b_name][0].key})"
            )
        rng.shuffle(kept)
        first_left = [i < len(kept) // 2 for i in range(len(kept))]
        if len(kept) % 2:
            first_left[-1] = rng.random() < 0.5
        rng.shuffle(first_left)
        for (ea, eb), a_left in zip(kept, first_left):
            (l_arm, le), (r_arm, re_) = ((a_name, ea), (b_name, eb)) if a_left else ((b_name, eb), (a_name, ea))
            pid = _new_pair_id(rng, used_ids)
            pairs.append(_pair_record(pid, ea, le, re_, media))
            key[pid] = {"left": l_arm, "right": r_arm, "source": ea.key}
        summary["comparisons"][label] = len(kept)
    rng.shuffle(pairs)
    study = {
        "format": FORMAT,
        "title": title or "Which looks more realistic?",
        "seed": seed,
        "kind": kinds.pop(),
        "arms": names,
        "baseline": baseline,
        "design": design,
        "pairs": pairs,
    }
    _atomic_json(
        out / "key.json",
        {
            "format": FORMAT,
            "baseline": baseline,
            "arm_dirs": {n: str(Path(a).resolve()) for n, a in zip(names, arms)},
            "pairs": key,
        },
    )
    _atomic_json(out / "study.json", study)  # last: its presence marks a complete study
    summary.update(pairs=len(pairs), out=str(out), baseline=baseline, arms=names)
    return summary


# ------------------------------------------------------------------------------------------------------ loading
@dataclass
class Study:
    """A built study: ``pairs`` as the page sees them (by id, in study order) and the held-back ``key``."""

    root: Path
    meta: dict
    key: dict
    pairs: dict[str, dict] = field(default_factory=dict)

    @property
    def arms(self) -> list[str]:
        return list(self.meta["arms"])

    @property
    def baseline(self) -> str:
        return self.meta["baseline"]

    def media_path(self, pair_id: str, side: str, index: int) -> Path | None:
        """The file of one side of a pair (``side`` "L" or "R"), or None if there is none; always inside media/."""
        pair = self.pairs.get(pair_id)
        if pair is None or side not in ("L", "R"):
            return None
        files = pair["left" if side == "L" else "right"]
        if not 0 <= index < len(files):
            return None
        p = (self.root / files[index]).resolve()
        media = (self.root / "media").resolve()
        if media not in p.parents or not p.is_file():
            return None
        return p


def load_study(path: str | Path) -> Study:
    root = Path(path)
    if not (root / "study.json").is_file():
        raise StudyError(f"{root}: no study.json (build one with `aias-abstudy build`)")
    meta = _read_json(root / "study.json")
    if meta.get("format") != FORMAT:
        raise StudyError(f"{root}/study.json: format {meta.get('format')!r}, expected {FORMAT!r}")
    key = _read_json(root / "key.json") if (root / "key.json").is_file() else None
    if key is None:
        raise StudyError(f"{root}: no key.json (the answer key); results cannot be computed without it")
    study = Study(root, meta, key["pairs"], {p["id"]: p for p in meta["pairs"]})
    missing = [pid for pid in study.pairs if pid not in study.key]
    if missing:
        raise StudyError(f"{root}: key.json lacks pairs {missing[:3]} (study.json and key.json do not belong together)")
    return study
