"""A study run records what besides its commit decides its numbers: a dirty tree is told apart from a clean one
(checked on a git repository made here), and the environment names torch's threads and CPU kernels."""

import subprocess

import torch

from detection_eval.study.pools import git_dirty, run_environment


def _git(root, *args):
    subprocess.run(["git", *args], cwd=root, check=True, capture_output=True)


def test_git_dirty_tells_an_edited_tracked_file_from_a_clean_or_untracked_one(tmp_path):
    assert git_dirty(tmp_path) is None  # not a repository
    _git(tmp_path, "init", "-q")
    (tmp_path / "a.txt").write_text("one\n")
    _git(tmp_path, "add", "a.txt")
    _git(tmp_path, "-c", "user.email=t@t", "-c", "user.name=t", "commit", "-q", "-m", "a")
    assert git_dirty(tmp_path) is False
    (tmp_path / "new.txt").write_text("untracked\n")
    assert git_dirty(tmp_path) is False  # untracked files do not change the code that ran
    (tmp_path / "a.txt").write_text("two\n")
    assert git_dirty(tmp_path) is True


def test_run_environment_names_the_threads_and_kernels_in_use():
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        env = run_environment()
        assert env["torch_threads"] == 1 and env["torch"] == torch.__version__
        assert env["cpu_capability"] in {"DEFAULT", "NO AVX", "AVX", "AVX2", "AVX512", "ZVECTOR", "VSX", "SVE256"}
    finally:
        torch.set_num_threads(before)
