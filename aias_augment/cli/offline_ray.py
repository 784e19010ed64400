"""``--backend ray``: the offline jobs as Ray tasks (Ray's own scheduling), on a cluster (``address``) or on a local
instance started here. Optional: ``pip install aias-augment[ray]``.

Each task runs :func:`aias_augment.cli.offline_job.process_item`, the same function as the local pool: per-image generator
``default_rng([seed, index])``, records and images written atomically to the shared output folder, a previous record
reused only when its input hash matches. So outputs are byte-identical to the local pool for the same seed, and
resume works the same way. Ray keeps its worker processes, so the renderer (an EGL context, created lazily by the
first render in a process) is created once per worker, never inherited.
"""

from __future__ import annotations

import os

from aias_augment.cli.offline_job import process_item


def _ray():
    try:
        import ray
    except ImportError:
        raise ImportError("--backend ray needs Ray: pip install 'aias-augment[ray]'") from None
    return ray


def run_jobs(jobs: list[tuple], workers: int, address: str | None = None, progress=None) -> list[dict]:
    """Records of ``jobs`` (``process_item`` argument tuples) in input order."""
    ray = _ray()
    started = False
    if not ray.is_initialized():
        env = {
            k: os.environ[k]
            for k in ("PYOPENGL_PLATFORM", "AIAS_DATA", "AIAS_CACHE", "NO_ALBUMENTATIONS_UPDATE")
            if k in os.environ
        }
        kw = dict(address=address, runtime_env={"env_vars": env}, log_to_driver=False)
        if address is None:  # a local instance sized like the pool
            kw.update(num_cpus=max(1, workers), include_dashboard=False)
        try:
            ray.init(**kw)
        except Exception as e:  # e.g. the raylet not registering within Ray's fixed 30 s on a starved machine
            ray.shutdown()  # stops what was started
            raise RuntimeError(f"Ray did not start ({address or 'local instance'}): {e}") from e
        started = True
    try:
        task = ray.remote(num_cpus=1, max_retries=2)(_task)
        refs = [task.remote(j) for j in jobs]
        pending = list(refs)
        while pending:  # progress as tasks finish; results are gathered in input order below
            done, pending = ray.wait(pending, num_returns=1)
            if progress is not None:
                progress.update(len(done))
        return ray.get(refs)
    finally:
        if started:
            ray.shutdown()


def _task(job: tuple) -> dict:
    return process_item(*job)
