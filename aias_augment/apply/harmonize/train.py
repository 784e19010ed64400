"""Training of the harmonization network (L1 + masked WGAN-GP) and of the fast colour-transform predictor.

The pair pool (object crops + masks at the network resolution) is built once from real images and cached under
``cache/``; perturbations are drawn fresh every step from a seeded ``numpy.random.Generator``, so a run is
reproducible given its config and seed.
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from aias_augment.apply.harmonize.checkpoint import load_checkpoint_dict
from aias_augment.apply.harmonize.fast import FastColorNet, FastConfig, apply_affine, save_fast_checkpoint, thumbnail
from aias_augment.apply.harmonize.network import (
    Critic,
    Generator,
    NetworkConfig,
    masked_gradient_penalty,
    save_checkpoint,
)
from aias_augment.apply.harmonize.pairs import (
    PerturbRanges,
    apply_perturbation,
    grabcut_mask,
    labelled_images,
    load_boxes,
    object_crop,
    random_region_mask,
    read_image_rgb,
    sample_perturbation,
)
from aias_augment.apply.harmonize.regions import mask_box
from aias_augment.core.config import REPO_ROOT, data_root, from_dict

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PairDataConfig:
    """Where training pairs come from (paths relative to ``data_root()``)."""

    labelled_images_dir: str = "tracon/images/train"
    labelled_labels: str = "tracon/labels/train"  # YOLO folder or COCO json
    unlabelled_globs: tuple[str, ...] = ("kitti06_color_snippet/*-color.png", "nyu_rgbd/color/*.png")
    regions_per_unlabelled_image: int = 2  # random blobs per image without boxes (incl. labelled-set images w/o boxes)
    regions_per_labelled_image: int = 0  # random blobs also on images that have boxes (more scenes per photo)
    max_objects_per_image: int = 4
    crops_per_object: int = 1  # context crops per segmented object, each with its own context factor
    min_box_px: int = 12
    context_range: tuple[float, float] = (1.8, 3.0)
    holdout_fraction: float = 0.05  # pool items kept out of training to monitor it


@dataclass(frozen=True)
class TrainConfig:
    network: NetworkConfig = field(default_factory=NetworkConfig)
    fast: FastConfig = field(default_factory=FastConfig)
    perturb: PerturbRanges = field(default_factory=PerturbRanges)
    data: PairDataConfig = field(default_factory=PairDataConfig)
    # The same random appearance change applied to the WHOLE crop (target and composite alike) with this probability
    # before the foreground is perturbed. Without it the small pool is memorised (the holdout fMSE of the fast model
    # rose from 293 to 450 between steps 1200 and 3200); with it only the object-vs-surroundings relation is learnable.
    scene_jitter_probability: float = 0.0
    scene_jitter: PerturbRanges = field(
        default_factory=lambda: PerturbRanges(blur_probability=0.0, noise_probability=0.0)
    )
    # "l1": DeepFill v1's masked L1 over the batch's foreground pixels; "fmse": mean over images of each image's
    # foreground MSE (the evaluation metric; small objects weigh as much as large ones).
    recon_loss: str = "l1"
    holdout_pairs: int = 48
    # Score the holdout on labelled objects only (what gets inserted), not on random regions: measured here, a
    # model selected on the mixed holdout was not the better one on held-out cones.
    holdout_objects_only: bool = False
    # "constant" or "cosine" (decay to 0 over ``steps``) for the network; ``fast_lr_schedule`` likewise over
    # ``fast_steps`` for the fast model. Step-based, so a run does not depend on the machine's speed.
    lr_schedule: str = "constant"
    fast_lr_schedule: str = "constant"
    seed: int = 0
    threads: int = 2
    # network
    steps: int = 3000
    time_limit_s: float = 900.0  # stop (and save) when training time passes this
    batch_size: int = 8
    lr_generator: float = 3e-4
    lr_critic: float = 3e-4
    global_lr_scale: float = 0.1  # learning-rate factor of the generator's global stage (see make_optimizers)
    betas_generator: tuple[float, float] = (0.9, 0.999)
    betas_critic: tuple[float, float] = (0.5, 0.9)  # DeepFill v1 / WGAN-GP
    l1_coarse_weight: float = 1.2  # DeepFill v1's l1_loss_alpha
    l1_refine_weight: float = 1.2
    gan_weight: float = 0.001  # DeepFill v1's gan_loss_alpha
    gp_weight: float = 10.0  # DeepFill v1's wgan_gp_lambda
    log_every: int = 25  # also how often the holdout is scored; the best-scoring generator is the one saved
    grad_clip_norm: float = 1.0
    # fast harmonizer
    fast_steps: int = 1500
    fast_time_limit_s: float = 240.0
    fast_batch_size: int = 32
    fast_lr: float = 1e-3


# ----------------------------------------------------------------------------------------------------------- the pool
@dataclass
class PairPool:
    images: np.ndarray  # (N, S, S, 3) uint8
    masks: np.ndarray  # (N, S, S) uint8 {0, 1}
    sources: list[str]


def build_pool(cfg: PairDataConfig, size_px: int, rng: np.random.Generator) -> PairPool:
    root = data_root()
    images, masks, sources = [], [], []
    skipped = {"grabcut": 0, "small": 0}

    def add(img, mask_bool, box, name):
        crop, m = object_crop(img, mask_bool, box, float(rng.uniform(*cfg.context_range)), size_px)
        if m.sum() >= 16:
            images.append(crop), masks.append(m.astype(np.uint8)), sources.append(name)

    def add_random_regions(img, name):
        for _ in range(cfg.regions_per_unlabelled_image):
            mb = random_region_mask(img.shape[:2], rng)
            add(img, mb, mask_box(mb), name + ":region")

    lab_dir, labels = root / cfg.labelled_images_dir, root / cfg.labelled_labels
    for path, boxes in labelled_images(lab_dir, labels):
        img = read_image_rgb(path)
        boxes = load_boxes(path, boxes, labels, img.shape[:2])
        if not boxes:
            add_random_regions(img, path.name)
            continue
        for _ in range(cfg.regions_per_labelled_image):
            mb = random_region_mask(img.shape[:2], rng)
            add(img, mb, mask_box(mb), path.name + ":region")
        order = rng.permutation(len(boxes))[: cfg.max_objects_per_image]
        for i in order:
            b = boxes[i]
            if min(b[2] - b[0], b[3] - b[1]) < cfg.min_box_px:
                skipped["small"] += 1
                continue
            mb = grabcut_mask(img, b)
            if mb is None:
                skipped["grabcut"] += 1
                continue
            for _ in range(cfg.crops_per_object):
                add(img, mb, b, path.name)
    for pattern in cfg.unlabelled_globs:
        for p in sorted(glob.glob(str(root / pattern))):
            add_random_regions(read_image_rgb(p), Path(p).name)
    log.info("pair pool: %d items, skipped %s", len(images), skipped)
    if not images:
        raise ValueError(f"no training pairs could be built from {root}")
    return PairPool(np.stack(images), np.stack(masks), sources)


def cached_pool(cfg: PairDataConfig, size_px: int, seed: int, cache_dir: Path = REPO_ROOT / "cache") -> PairPool:
    key = hashlib.sha1(json.dumps([dataclasses.asdict(cfg), size_px, seed, str(data_root())]).encode()).hexdigest()[:12]
    path = cache_dir / f"harmonize_pool_{size_px}_{key}.npz"
    if path.exists():
        z = np.load(path)
        return PairPool(z["images"], z["masks"], list(z["sources"]))
    pool = build_pool(cfg, size_px, np.random.default_rng(seed))
    cache_dir.mkdir(parents=True, exist_ok=True)
    np.savez(path, images=pool.images, masks=pool.masks, sources=np.array(pool.sources))
    return pool


def source_photo(source: str) -> str:
    """The photo a pool item comes from (random-region items carry a ':region' suffix)."""
    return source.split(":", 1)[0]


def split_pool(pool: PairPool, holdout_fraction: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Indices (train, holdout); holdout is split by *source photo* so no photo is on both sides (its objects and
    its random regions go together)."""
    photos = [source_photo(s) for s in pool.sources]
    names = sorted(set(photos))
    held = set(rng.permutation(names)[: max(1, int(round(holdout_fraction * len(names))))].tolist())
    idx = np.arange(len(pool.sources))
    is_held = np.array([p in held for p in photos])
    return idx[~is_held], idx[is_held]


def make_batch(
    pool: PairPool,
    idx: np.ndarray,
    perturb: PerturbRanges,
    rng: np.random.Generator,
    flip: bool = True,
    scene_jitter: PerturbRanges | None = None,
    scene_jitter_probability: float = 0.0,
):
    """(composite, target, mask) tensors (B,3,S,S), (B,3,S,S), (B,1,S,S) in [0, 1].

    ``scene_jitter``: with ``scene_jitter_probability`` the whole crop is first changed in appearance (the target
    too), so the absolute colours of a pool item cannot be memorised.
    """
    comps, targets, masks = [], [], []
    for i in idx:
        img, m = pool.images[i], pool.masks[i].astype(np.float32)
        if flip and rng.random() < 0.5:
            img, m = img[:, ::-1], m[:, ::-1]
        if scene_jitter is not None and rng.random() < scene_jitter_probability:
            img = apply_perturbation(img, np.ones(m.shape, np.float32), sample_perturbation(scene_jitter, rng), rng)
        comps.append(apply_perturbation(img, m, sample_perturbation(perturb, rng), rng))
        targets.append(img), masks.append(m)

    def to_t(a):
        return torch.from_numpy(np.ascontiguousarray(np.stack(a))).permute(0, 3, 1, 2).float() / 255.0

    return to_t(comps), to_t(targets), torch.from_numpy(np.ascontiguousarray(np.stack(masks)))[:, None]


def masked_l1(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """L1 over foreground pixels, normalised by foreground area (+1 pixel so an empty mask gives 0)."""
    return ((pred - target).abs() * mask).sum() / (3 * mask.sum() + 1.0)


def masked_mse_per_image(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean over images of each image's foreground MSE ([0, 1] units; +1 pixel so an empty mask gives 0)."""
    err = ((pred - target).pow(2) * mask).sum(dim=(1, 2, 3)) / (3 * mask.sum(dim=(1, 2, 3)) + 1.0)
    return err.mean()


# fMSE ([0,1] units, typically 1e-3..1e-2) is scaled to the magnitude of the L1 loss so the DeepFill loss weights
# (L1 alpha 1.2, GAN alpha 0.001) keep their balance whichever reconstruction loss is chosen.
FMSE_LOSS_SCALE = 30.0


def recon_loss(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, kind: str) -> torch.Tensor:
    if kind == "l1":
        return masked_l1(pred, target, mask)
    if kind == "fmse":
        return FMSE_LOSS_SCALE * masked_mse_per_image(pred, target, mask)
    raise ValueError(f"recon_loss must be 'l1' or 'fmse', got {kind!r}")


def batch_for_training(pool: PairPool, idx: np.ndarray, cfg: "TrainConfig", rng: np.random.Generator):
    return make_batch(
        pool,
        idx,
        cfg.perturb,
        rng,
        scene_jitter=cfg.scene_jitter,
        scene_jitter_probability=cfg.scene_jitter_probability,
    )


def fmse_255(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> float:
    """Mean over the batch of per-image fMSE on the 0..255 scale (same definition as ``metrics.fmse``)."""
    err = ((pred.detach() - target) * 255).pow(2) * mask
    return float((err.sum(dim=(1, 2, 3)) / (3 * mask.sum(dim=(1, 2, 3)).clamp_min(1))).mean())


def _fixed_holdout(pool, hold_idx, cfg: TrainConfig):
    if cfg.holdout_objects_only:
        objects = hold_idx[[":region" not in pool.sources[i] for i in hold_idx]]
        hold_idx = objects if len(objects) else hold_idx
    rng = np.random.default_rng(cfg.seed + 1)
    idx = hold_idx[np.linspace(0, len(hold_idx) - 1, min(cfg.holdout_pairs, len(hold_idx))).astype(int)]
    return make_batch(pool, idx, cfg.perturb, rng, flip=False)


# -------------------------------------------------------------------------------------------------------- the network
def train_step(
    gen: Generator, critic: Critic, opt_g, opt_d, comp, target, mask, cfg: TrainConfig, tgen: torch.Generator
) -> dict[str, float]:
    """One critic update (WGAN loss + mask-weighted GP, its interpolates drawn from ``tgen``) then one generator
    update (L1 coarse + L1 refined + adv)."""
    out = gen(comp, mask)
    opt_d.zero_grad()
    d_real, d_fake = critic(target, mask), critic(out["output"].detach(), mask)
    gp = masked_gradient_penalty(critic, target, out["output"], mask, tgen)
    loss_d = d_fake.mean() - d_real.mean() + cfg.gp_weight * gp
    loss_d.backward()
    opt_d.step()
    opt_g.zero_grad()
    l1_c = recon_loss(out["coarse"], target, mask, cfg.recon_loss)
    l1_r = recon_loss(out["output"], target, mask, cfg.recon_loss)
    adv = -critic(out["output"], mask).mean()
    loss_g = cfg.l1_coarse_weight * l1_c + cfg.l1_refine_weight * l1_r + cfg.gan_weight * adv
    if "global" in out:  # deep supervision of the global stage, weighted as the coarse stage
        loss_g = loss_g + cfg.l1_coarse_weight * recon_loss(out["global"], target, mask, cfg.recon_loss)
    loss_g.backward()
    torch.nn.utils.clip_grad_norm_(gen.parameters(), cfg.grad_clip_norm)
    opt_g.step()
    return {
        k: float(v.detach())
        for k, v in {"l1_coarse": l1_c, "l1_refine": l1_r, "loss_d": loss_d, "gp": gp, "adv": adv}.items()
    }


def make_optimizers(gen: Generator, critic: Critic, cfg: TrainConfig):
    """Adam for both; the generator's global stage (when present) learns at ``global_lr_scale`` x the rate: it
    starts trained (from the fast harmonizer, batch 32) and batch-8 steps at the full rate only shake it. Scale 0
    freezes it."""
    glob = [] if gen.global_stage is None else list(gen.global_stage.parameters())
    ids = {id(p) for p in glob}
    rest = [p for p in gen.parameters() if id(p) not in ids]
    if cfg.global_lr_scale == 0.0:  # frozen: no gradients are computed for it
        for p in glob:
            p.requires_grad_(False)
        glob = []
    groups = [{"params": rest}] + ([{"params": glob, "lr": cfg.lr_generator * cfg.global_lr_scale}] if glob else [])
    return (
        torch.optim.Adam(groups, lr=cfg.lr_generator, betas=cfg.betas_generator),
        torch.optim.Adam(critic.parameters(), lr=cfg.lr_critic, betas=cfg.betas_critic),
    )


def _load_initial_weights(gen: Generator, cfg: TrainConfig, init_from, init_global_from) -> tuple[dict, list]:
    """Load ``init_from`` (a saved generator of the same network config) and ``init_global_from`` (a fast-harmonizer
    checkpoint for the global stage) into ``gen``; returns what the run continues from (its steps, training time and
    history) and the earlier run's segments."""
    prior = {"steps": 0, "train_time_s": 0.0, "history": []}
    segments: list = []
    if init_from is not None:
        ckpt = load_checkpoint_dict(init_from, "network")
        if from_dict(NetworkConfig, ckpt["config"]) != cfg.network:
            raise ValueError(f"{init_from}: network config differs from the training config")
        gen.load_state_dict(ckpt["state_dict"])
        prior = {k: ckpt["meta"].get(k, prior[k]) for k in prior}
        segments = list(ckpt["meta"].get("segments", []))
    if init_global_from is not None:
        if gen.global_stage is None:
            raise ValueError("init_global_from needs network.global_stage: true")
        fast = load_checkpoint_dict(init_global_from, "fast")
        if from_dict(FastConfig, fast["config"]) != gen.global_stage.cfg:
            raise ValueError(f"{init_global_from}: fast config {fast['config']} differs from the global stage's")
        gen.global_stage.load_state_dict(fast["state_dict"])
    return prior, segments


def train_network(
    cfg: TrainConfig,
    out_path: str | Path,
    pool: PairPool | None = None,
    meta: dict | None = None,
    init_from: str | Path | None = None,
    init_global_from: str | Path | None = None,
) -> dict:
    """Train the generator + critic; returns a summary. ``out_path`` holds the generator that scored best on the
    holdout so far (rewritten at each improvement, so a stopped run keeps its best model).

    ``init_from``: continue from a saved generator (same network config); its steps and training time are carried
    into the summary (the critic and optimiser states start afresh). ``init_global_from``: a fast-harmonizer
    checkpoint whose weights start the generator's global stage (``network.global_stage``).
    """
    torch.set_num_threads(cfg.threads)
    rng = np.random.default_rng(cfg.seed)
    tgen = torch.Generator().manual_seed(cfg.seed)
    pool = pool or cached_pool(cfg.data, cfg.network.resolution_px, cfg.seed)
    train_idx, hold_idx = split_pool(pool, cfg.data.holdout_fraction, np.random.default_rng(cfg.seed))
    hold = _fixed_holdout(pool, hold_idx, cfg)
    with torch.random.fork_rng(devices=[]):  # weight init seeded by cfg.seed; the process' torch state untouched
        torch.manual_seed(cfg.seed)
        gen, critic = Generator(cfg.network), Critic(cfg.network.critic_channels)
    prior, prior_segments = _load_initial_weights(gen, cfg, init_from, init_global_from)
    opt_g, opt_d = make_optimizers(gen, critic, cfg)
    scheds = [torch.optim.lr_scheduler.LambdaLR(o, lr_lambda(cfg.lr_schedule, cfg.steps)) for o in (opt_g, opt_d)]
    history, t0, step = list(prior["history"]), time.perf_counter(), 0

    def evaluate():
        gen.eval()
        with torch.no_grad():
            out = gen(hold[0], hold[2])["output"]
        gen.train()
        return fmse_255(hold[0], hold[1], hold[2]), fmse_255(out, hold[1], hold[2])

    raw_fmse, best_fmse = evaluate()
    best_step, best_state = prior["steps"], {k: v.detach().clone() for k, v in gen.state_dict().items()}

    def summarize(step: int, elapsed: float) -> dict:
        return {
            "steps": prior["steps"] + step,
            "best_step": best_step,
            "train_time_s": round(prior["train_time_s"] + elapsed, 1),
            "segments": [
                *prior_segments,
                {"steps": step, "train_time_s": round(elapsed, 1), "init_from": str(init_from)},
            ],
            "holdout_raw_fmse": raw_fmse,
            "holdout_fmse": best_fmse,
            "pool_items": len(pool.sources),
            "threads": cfg.threads,
            "config": dataclasses.asdict(cfg),
            "history": history,
            **(meta or {}),
        }

    log.info("holdout: %d pairs, raw composite fMSE %.1f", hold[0].shape[0], raw_fmse)
    save_checkpoint(out_path, gen, summarize(0, 0.0))
    for step in range(1, cfg.steps + 1):
        comp, target, mask = batch_for_training(pool, rng.choice(train_idx, cfg.batch_size), cfg, rng)
        losses = train_step(gen, critic, opt_g, opt_d, comp, target, mask, cfg, tgen)
        for sc in scheds:
            sc.step()
        elapsed = time.perf_counter() - t0
        done = elapsed > cfg.time_limit_s or step == cfg.steps
        if step % cfg.log_every == 0 or done:
            _, net_fmse = evaluate()
            rec = {
                "step": prior["steps"] + step,
                "time_s": round(prior["train_time_s"] + elapsed, 1),
                **losses,
                "holdout_fmse": net_fmse,
            }
            history.append(rec)
            log.info(
                "step %d %.0fs l1 %.4f/%.4f D %.3f gp %.3f holdout fMSE %.1f (raw %.1f)",
                step,
                elapsed,
                rec["l1_coarse"],
                rec["l1_refine"],
                rec["loss_d"],
                rec["gp"],
                net_fmse,
                raw_fmse,
            )
            if net_fmse < best_fmse:  # keep the generator that scores best on the holdout (training images)
                best_fmse, best_step = net_fmse, prior["steps"] + step
                best_state = {k: v.detach().clone() for k, v in gen.state_dict().items()}
                save_checkpoint(out_path, gen, summarize(step, elapsed))
        if done:
            break
    # The best weights with the whole run's record (steps and time include those after the best step).
    gen.load_state_dict(best_state)
    summary = summarize(step, elapsed)
    save_checkpoint(out_path, gen, summary)
    return summary


# --------------------------------------------------------------------------------------------------- fast harmonizer
def fast_predict(model: FastColorNet, comp: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    thumb, tm = thumbnail(comp, mask, model.cfg.in_px)
    return mask * apply_affine(comp, model(thumb, tm)) + (1 - mask) * comp


def fast_train_step(model: FastColorNet, opt, comp, target, mask, kind: str = "l1") -> float:
    loss = recon_loss(fast_predict(model, comp, mask), target, mask, kind)
    opt.zero_grad()
    loss.backward()
    opt.step()
    return float(loss.detach())


def lr_lambda(schedule: str, total_steps: int):
    if schedule == "constant":
        return lambda step: 1.0
    if schedule == "cosine":
        return lambda step: 0.5 * (1.0 + np.cos(np.pi * min(step, total_steps) / max(total_steps, 1)))
    raise ValueError(f"lr_schedule must be 'constant' or 'cosine', got {schedule!r}")


def train_fast(
    cfg: TrainConfig,
    out_path: str | Path,
    pool: PairPool | None = None,
    meta: dict | None = None,
    init_from: str | Path | None = None,
) -> dict:
    """Train the fast harmonizer; ``out_path`` holds the model that scored best on the holdout (as the network).
    ``init_from``: start from a saved fast checkpoint (same config)."""
    torch.set_num_threads(cfg.threads)
    rng = np.random.default_rng(cfg.seed + 7)
    pool = pool or cached_pool(cfg.data, cfg.network.resolution_px, cfg.seed)
    train_idx, hold_idx = split_pool(pool, cfg.data.holdout_fraction, np.random.default_rng(cfg.seed))
    hold = _fixed_holdout(pool, hold_idx, cfg)
    with torch.random.fork_rng(devices=[]):  # weight init seeded by cfg.seed; the process' torch state untouched
        torch.manual_seed(cfg.seed)
        model = FastColorNet(cfg.fast)
    if init_from is not None:
        ckpt = load_checkpoint_dict(init_from, "fast")
        if from_dict(FastConfig, ckpt["config"]) != cfg.fast:
            raise ValueError(f"{init_from}: fast config differs from the training config")
        model.load_state_dict(ckpt["state_dict"])
    opt = torch.optim.Adam(model.parameters(), lr=cfg.fast_lr)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lr_lambda(cfg.fast_lr_schedule, cfg.fast_steps))

    def evaluate():
        with torch.no_grad():
            return fmse_255(fast_predict(model, hold[0], hold[2]), hold[1], hold[2])

    raw = fmse_255(hold[0], hold[1], hold[2])
    best_fmse, best_step, best_state = raw, 0, {k: v.detach().clone() for k, v in model.state_dict().items()}
    t0, history, step = time.perf_counter(), [], 0
    for step in range(1, cfg.fast_steps + 1):
        comp, target, mask = batch_for_training(pool, rng.choice(train_idx, cfg.fast_batch_size), cfg, rng)
        loss = fast_train_step(model, opt, comp, target, mask, cfg.recon_loss)
        sched.step()
        elapsed = time.perf_counter() - t0
        done = elapsed > cfg.fast_time_limit_s or step == cfg.fast_steps
        if step % (cfg.log_every * 4) == 0 or done:
            score = evaluate()
            history.append({"step": step, "time_s": round(elapsed, 1), "loss": loss, "holdout_fmse": score})
            log.info("fast step %d %.0fs loss %.4f holdout fMSE %.1f (raw %.1f)", step, elapsed, loss, score, raw)
            if score < best_fmse:
                best_fmse, best_step = score, step
                best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        if done:
            break
    model.load_state_dict(best_state)
    summary = {
        "steps": step,
        "best_step": best_step,
        "train_time_s": round(time.perf_counter() - t0, 1),
        "init_from": None if init_from is None else str(init_from),
        "holdout_raw_fmse": raw,
        "holdout_fmse": best_fmse,
        "pool_items": len(pool.sources),
        "threads": cfg.threads,
        "config": dataclasses.asdict(cfg),
        "history": history,
        **(meta or {}),
    }
    save_fast_checkpoint(out_path, model, summary)
    return summary


# ------------------------------------------------------------------------------------------ camera-matching strengths
def tune_camera_strengths(
    cfg: TrainConfig,
    pool: PairPool | None = None,
    n_pairs: int = 60,
    grid: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0),
) -> dict:
    """Grid-search ``exposure_strength`` x ``wb_strength`` of the camera matching on *training* pairs (fMSE).

    Only the gain stage is searched (blur/noise/JPEG off): those stages cannot undo a perturbation, they add the
    scene's degradations to clean renders.
    """
    from aias_augment.apply.harmonize.camera_pipeline import CameraMatchParams, camera_match
    from aias_augment.apply.harmonize.metrics import fmse

    pool = pool or cached_pool(cfg.data, cfg.network.resolution_px, cfg.seed)
    train_idx, _ = split_pool(pool, cfg.data.holdout_fraction, np.random.default_rng(cfg.seed))
    rng = np.random.default_rng(cfg.seed + 11)
    idx = rng.choice(train_idx, min(n_pairs, len(train_idx)), replace=False)
    pairs = []
    for i in idx:
        m = pool.masks[i].astype(np.float32)
        pairs.append(
            (
                apply_perturbation(pool.images[i], m, sample_perturbation(cfg.perturb, rng), rng),
                pool.images[i],
                m.astype(bool),
            )
        )
    table = {}
    for e in grid:
        for w in grid:
            p = CameraMatchParams(
                exposure_strength=e, wb_strength=w, match_sharpness=False, match_noise=False, match_jpeg=False
            )
            table[(e, w)] = float(np.mean([fmse(camera_match(c, m, rng, p), t, m) for c, t, m in pairs]))
    best = min(table, key=table.get)
    raw = float(np.mean([fmse(c, t, m) for c, t, m in pairs]))
    return {
        "pairs": len(pairs),
        "raw_fmse": raw,
        "best": {"exposure_strength": best[0], "wb_strength": best[1]},
        "best_fmse": table[best],
        "table": {f"{e},{w}": v for (e, w), v in table.items()},
    }
