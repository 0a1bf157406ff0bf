"""The allocator settings (skeleton_mamba/runtime/allocator.py): memory a step frees is reused, not faulted
in again; nothing changes where the user chose malloc settings, off glibc, or outside training commands."""

from __future__ import annotations

import platform
import subprocess
import sys

import pytest

from skeleton_mamba.runtime import allocator
from skeleton_mamba.tasks.training import cli

GLIBC = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"

# A "step" that allocates, writes and frees blocks of 1 to 24 MB, as a training step's intermediates; the
# process prints the minor page faults of the last 5 of 8 steps. Every process starts from glibc's own
# starting thresholds (128 KiB each, set explicitly): glibc adapts them to what the process freed so far,
# so a fresh interpreter's state depends on what its imports did (on one machine the pattern faulted in
# every page, on another none), and the comparison would not be about keep_freed_memory.
STEPS = """
import ctypes, resource, sys, torch
from skeleton_mamba.runtime.allocator import keep_freed_memory
mallopt = ctypes.CDLL(None).mallopt
assert mallopt(-3, 128 << 10) == 1 and mallopt(-1, 128 << 10) == 1  # M_MMAP_THRESHOLD, M_TRIM_THRESHOLD
print(keep_freed_memory() if sys.argv[1] == "tuned" else False)
def step():
    kept = [torch.ones(n << 18) for n in (24, 4, 16, 1, 8, 12, 2)]  # n MB of fp32 each, written
    del kept
for _ in range(3):
    step()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(5):
    step()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> tuple[bool, int]:
    out = subprocess.run(
        [sys.executable, "-c", STEPS, mode], capture_output=True, text=True, check=True, env={"PATH": ""}
    ).stdout.split()
    return out[0] == "True", int(out[1])


@pytest.mark.skipif(not GLIBC, reason="the settings are glibc's (Linux with glibc only)")
def test_freed_blocks_are_reused_instead_of_faulted_in_again():
    # the fewest of three runs: a busy machine reclaiming pages adds faults from outside the allocator (one
    # CI run under load counted 3584 in a single run)
    runs = [_faults("tuned") for _ in range(3)]
    tuned, faults_tuned = all(ok for ok, _ in runs), min(n for _, n in runs)
    untuned, faults_default = _faults("start")
    assert tuned and not untuned
    pages = (24 + 4 + 16 + 1 + 8 + 12 + 2) * 5 * (1 << 20) // 4096  # every page of every block, 5 steps
    assert faults_default > pages // 4  # glibc's starting thresholds: much of it handed back and faulted in
    assert faults_tuned < pages // 50  # reused: a few page faults, not one per page


def test_user_settings_and_other_c_libraries_are_left_alone(monkeypatch):
    for name in ("GLIBC_TUNABLES", "MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TOP_PAD_"):
        assert allocator.keep_freed_memory({name: "1"}) is False
    monkeypatch.setattr(allocator.platform, "libc_ver", lambda: ("musl", "1.2"))
    assert allocator.keep_freed_memory({}) is False
    monkeypatch.setattr(allocator.platform, "system", lambda: "Darwin")
    assert allocator.keep_freed_memory({}) is False


@pytest.mark.parametrize(("command", "called"), [("fit", True), ("test", True), ("analyze-music", False)])
def test_only_the_lightning_commands_keep_freed_memory(monkeypatch, command, called):
    calls = []
    monkeypatch.setattr(cli, "keep_freed_memory", lambda: calls.append(command))
    with pytest.raises(SystemExit):  # --help prints the command's usage and exits
        cli.main([command, "--help"])
    assert bool(calls) is called
