"""``sm``'s thread defaults (one intra-op thread on a small machine, a passive OpenMP wait policy, unless the
user set them)
and the real-time hint naming the fix."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import torch

from skeleton_mamba.tasks.training.frame_timing import realtime_hint
from skeleton_mamba.tasks.training.threads import SMALL_MACHINE_CORES, apply_thread_defaults

LATE = {"median_ms": 20.0, "p99_ms": 371.0, "max_ms": 500.0}  # the p99 reported under load
ON_TIME = {"median_ms": 3.0, "p99_ms": 19.0, "max_ms": 25.0}


@pytest.fixture
def torch_threads():
    before = torch.get_num_threads()
    yield
    torch.set_num_threads(before)


def test_defaults_fill_only_what_the_environment_lacks(torch_threads):
    torch.set_num_threads(2)
    env: dict[str, str] = {}
    assert apply_thread_defaults(env, cores=2) == 1 == torch.get_num_threads()
    assert env == {"OMP_NUM_THREADS": "1", "OMP_WAIT_POLICY": "PASSIVE"}

    torch.set_num_threads(2)
    env = {"OMP_NUM_THREADS": "2", "OMP_WAIT_POLICY": "ACTIVE"}
    assert apply_thread_defaults(env, cores=2) == 2  # the user's count: torch left as it was
    assert env == {"OMP_NUM_THREADS": "2", "OMP_WAIT_POLICY": "ACTIVE"}

    env = {"OMP_WAIT_POLICY": "ACTIVE"}  # only the count is sm's
    assert apply_thread_defaults(env, cores=2) == 1
    assert env == {"OMP_WAIT_POLICY": "ACTIVE", "OMP_NUM_THREADS": "1"}


def test_a_large_machine_keeps_torchs_thread_count(torch_threads):
    torch.set_num_threads(3)
    env: dict[str, str] = {}
    assert apply_thread_defaults(env, cores=SMALL_MACHINE_CORES + 1) == 3  # a paper-size model uses its cores
    assert env == {"OMP_WAIT_POLICY": "PASSIVE"}
    env = {}
    assert apply_thread_defaults(env, cores=SMALL_MACHINE_CORES) == 1 and env["OMP_NUM_THREADS"] == "1"


PROBE = (
    "import json, os, sys, torch; from skeleton_mamba.tasks.training.cli import main; "
    "code = main(['recipes']); print(json.dumps([code, torch.get_num_threads(), "
    "os.environ.get('OMP_NUM_THREADS'), os.environ.get('OMP_WAIT_POLICY')]))"
)


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ({}, [0, 1, "1", "PASSIVE"]),
        ({"OMP_NUM_THREADS": "2"}, [0, 2, "2", "PASSIVE"]),
        ({"OMP_NUM_THREADS": "2", "OMP_WAIT_POLICY": "ACTIVE"}, [0, 2, "2", "ACTIVE"]),
    ],
)
def test_the_sm_entry_applies_the_defaults_and_respects_the_users_values(env, expected):
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "OMP_WAIT_POLICY")}
    done = subprocess.run(
        [sys.executable, "-c", PROBE], env={**base, **env}, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == expected


def test_torch_imported_after_the_entry_starts_with_its_thread_defaults():
    """``sm`` imports no torch before a command runs: the defaults reach torch through the environment."""
    probe = (
        "import json, os, sys; from skeleton_mamba.tasks.training.cli import main; code = main(['recipes']); "
        "before = 'torch' in sys.modules; import torch; "
        "print(json.dumps([code, before, torch.get_num_threads(), os.environ.get('OMP_WAIT_POLICY')]))"
    )
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "OMP_WAIT_POLICY")}
    done = subprocess.run(
        [sys.executable, "-c", probe], env=base, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == [0, False, 1, "PASSIVE"]
    env: dict[str, str] = {}
    assert apply_thread_defaults(env, cores=2) == torch.get_num_threads()  # torch imported here: its count


def test_the_realtime_hint_names_one_thread_then_compile(monkeypatch):
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    hint = realtime_hint(LATE, compiled=False, fps=30, threads=2)
    assert hint.startswith("sm stream: the p99 latency (371 ms) is above one 30 fps frame (33.3 ms)")
    assert (
        "it ran on 2 threads: one thread (--threads 1, or OMP_NUM_THREADS=1 OMP_WAIT_POLICY=PASSIVE)" in hint
    )
    assert hint.index("--threads 1") < hint.index("--compile")
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")  # already set: not offered again
    assert "OMP_WAIT_POLICY" not in realtime_hint(LATE, compiled=True, fps=30, threads=4)
    assert "--compile" not in realtime_hint(LATE, compiled=True, fps=30, threads=4)
    one = realtime_hint(LATE, compiled=False, fps=30, threads=1)
    assert "--compile" in one and "thread" not in one
    assert realtime_hint(LATE, compiled=True, fps=30, threads=1) is None  # nothing left to offer
    assert realtime_hint(ON_TIME, compiled=False, fps=30, threads=2) is None  # 19 ms < 33.3 ms
    assert realtime_hint(ON_TIME, compiled=False, fps=60, threads=2) is not None  # 19 ms > 16.7 ms
    assert realtime_hint({k: float("nan") for k in LATE}, compiled=False, fps=30, threads=2) is None
