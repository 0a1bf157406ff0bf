"""The CPU thread defaults of every ``sm`` command: one intra-op thread on a small machine unless the user
says otherwise.

The project's CPU work is many small kernels (a tiny demo backbone, one pose per frame in ``sm stream``):
split over several OpenMP threads, each kernel waits for the slowest thread, and on a machine that is also
running other jobs a descheduled thread stalls every kernel while the others spin. One thread does not
wait for anyone. On a machine of at most :data:`SMALL_MACHINE_CORES` cores, where a second thread gains at
most a few tens of percent on a quiet machine and one busy neighbour costs several times that, ``sm`` runs
torch on one intra-op thread and passes ``OMP_NUM_THREADS=1`` on to the processes it starts, unless
``OMP_NUM_THREADS`` is set; on a larger machine torch's own count stays (a paper-size model gains from its
cores). Everywhere it passes ``OMP_WAIT_POLICY=PASSIVE`` (idle OpenMP threads sleep instead of spinning).
A user's own ``OMP_NUM_THREADS`` / ``OMP_WAIT_POLICY`` wins, as does ``sm stream --threads N``.

``import torch`` starts OpenMP and reads these variables then. ``sm`` sets them before any command imports
torch (its command table imports none), so torch starts with them; where torch is already imported (a
caller that imported it first) the count is also set through ``torch.set_num_threads``. The variables
serve the child processes too.
"""

from __future__ import annotations

import os
import sys
from collections.abc import MutableMapping

__all__ = ["DEFAULT_ENV", "SMALL_MACHINE_CORES", "THREADS_HELP", "apply_thread_defaults", "available_cores"]

DEFAULT_ENV = {"OMP_NUM_THREADS": "1", "OMP_WAIT_POLICY": "PASSIVE"}
SMALL_MACHINE_CORES = 4
THREADS_HELP = (  # the live commands' --threads
    "torch CPU threads (default: OMP_NUM_THREADS if set, else 1 on a machine of at most "
    f"{SMALL_MACHINE_CORES} cores and torch's count on a larger one)"
)


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS tells it, else ``os.cpu_count()``)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def apply_thread_defaults(
    environ: MutableMapping[str, str] | None = None, cores: int | None = None
) -> int | None:
    """Set ``OMP_WAIT_POLICY=PASSIVE`` where ``environ`` (default ``os.environ``) lacks it, and on a machine
    of ``cores`` (default :func:`available_cores`) <= :data:`SMALL_MACHINE_CORES` without ``OMP_NUM_THREADS``
    one thread (``OMP_NUM_THREADS=1``, and torch's count when torch is already imported); returns torch's
    thread count, or None when torch is not imported yet (it reads the variables when it is)."""
    environ = os.environ if environ is None else environ
    cores = available_cores() if cores is None else cores
    torch = sys.modules.get("torch")  # imported by the caller, or not yet: then it starts with the variables
    if "OMP_NUM_THREADS" not in environ and cores <= SMALL_MACHINE_CORES:
        environ["OMP_NUM_THREADS"] = DEFAULT_ENV["OMP_NUM_THREADS"]
        if torch is not None:
            torch.set_num_threads(int(DEFAULT_ENV["OMP_NUM_THREADS"]))
    environ.setdefault("OMP_WAIT_POLICY", DEFAULT_ENV["OMP_WAIT_POLICY"])
    return None if torch is None else torch.get_num_threads()
