"""librosa's numba kernels compile into the project's own cache folder, one process at a time (issue 61,
item 5): several ``sm analyze-music`` processes started at once on a fresh cache, then again on the cache
they left, all finish with the same features; the user's ``NUMBA_CACHE_DIR`` is kept."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.music import jit_lock
from skeleton_mamba.tasks.motion.synthetic import synthesize_music
from skeleton_mamba.tasks.motion.synthetic.music import write_music

PROCESSES = 3


def _analyse_at_once(song, out, env) -> list[np.ndarray]:
    """Start :data:`PROCESSES` ``sm analyze-music`` processes together; their features."""
    command = [
        sys.executable,
        "-m",
        "skeleton_mamba.tasks",
        "analyze-music",
        str(song),
        "--no-cache",
        "--out",
    ]
    pipes = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True}
    runs = [
        subprocess.Popen([*command, str(out / f"features{i}.npy")], env=env, **pipes)
        for i in range(PROCESSES)
    ]
    for i, run in enumerate(runs):
        stdout, stderr = run.communicate(timeout=600)
        assert run.returncode == 0, f"process {i} exited {run.returncode} (negative: a signal)\n{stderr}"
    return [np.load(out / f"features{i}.npy") for i in range(PROCESSES)]


def test_processes_compiling_at_once_share_one_cache_safely(tmp_path):
    song = write_music(tmp_path / "song.wav", synthesize_music(120.0, 4.0, sr=22050, seed=3))
    cache = tmp_path / "cache"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["SKELETON_MAMBA_CACHE"] = str(cache)
    first = _analyse_at_once(song, tmp_path, env)
    kernels = list((cache / "numba").rglob("*.nbi"))
    assert kernels, "numba cached no kernel in the project's folder"
    again = _analyse_at_once(song, tmp_path, env)  # the cache the first ones left
    for features in first[1:] + again:
        np.testing.assert_array_equal(features, first[0])
    assert first[0].shape[1] == 35


def test_the_users_numba_cache_dir_is_kept(tmp_path, monkeypatch):
    monkeypatch.setenv("SKELETON_MAMBA_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert jit_lock.numba_cache_dir() == tmp_path / "mine"
    assert jit_lock.lock_path().parent == tmp_path / "mine"
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert jit_lock.numba_cache_dir() == tmp_path / "cache" / "numba"
    with jit_lock.librosa_lock():
        assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "cache" / "numba")


def test_the_lock_excludes_other_threads_and_nests_in_one(tmp_path, monkeypatch):
    pytest.importorskip("fcntl")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    order: list[str] = []
    with jit_lock.librosa_lock():
        with jit_lock.librosa_lock():  # nested in one thread: no deadlock
            worker = threading.Thread(target=lambda: _locked(order))
            worker.start()
            worker.join(0.3)
            assert worker.is_alive()  # waits for this thread's lock
            order.append("main")
    worker.join(10)
    assert order == ["main", "worker"]


def _locked(order: list[str]) -> None:
    with jit_lock.librosa_lock():
        order.append("worker")


def test_a_warm_path_takes_the_lock_on_its_first_run_only(tmp_path, monkeypatch):
    """A live stream's per-frame features: locked the first time (librosa imported, kernels compiled), then
    never held, so another process' long analysis cannot stall the stream."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(jit_lock, "_warm_paths", set())
    held = []
    real = jit_lock.librosa_lock
    monkeypatch.setattr(jit_lock, "librosa_lock", lambda: held.append(1) or real())
    for _ in range(3):
        with jit_lock.librosa_calls(warm_path="frames") as librosa:
            assert librosa.__name__ == "librosa"
    assert held == [1]
    with jit_lock.librosa_calls():  # any other call: every time
        pass
    assert held == [1, 1]
