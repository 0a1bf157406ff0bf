"""The CPU thread defaults of every ``sm`` command: one intra-op thread unless the user says otherwise.

The project's CPU work is many small kernels (a tiny demo backbone, one pose per frame in ``sm stream``):
split over several OpenMP threads, each kernel waits for the slowest thread, and on a machine that is also
running other jobs a descheduled thread stalls every kernel while the others spin. One thread does not
wait for anyone. So, unless ``OMP_NUM_THREADS`` is set, ``sm`` runs torch on one intra-op thread and passes
``OMP_NUM_THREADS=1`` and ``OMP_WAIT_POLICY=PASSIVE`` (idle OpenMP threads sleep instead of spinning) on
to the processes it starts. A user's own ``OMP_NUM_THREADS`` / ``OMP_WAIT_POLICY`` wins, as does
``sm stream --threads N``.

``import torch`` starts OpenMP and reads these variables then; ``sm`` has imported torch by the time its
entry runs (the package's ``__init__`` imports the backbone), so the thread count is set through
``torch.set_num_threads``, before any torch work, and the variables serve the child processes.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping

import torch

__all__ = ["DEFAULT_ENV", "apply_thread_defaults"]

DEFAULT_ENV = {"OMP_NUM_THREADS": "1", "OMP_WAIT_POLICY": "PASSIVE"}


def apply_thread_defaults(environ: MutableMapping[str, str] | None = None) -> int:
    """Set :data:`DEFAULT_ENV` where ``environ`` (default ``os.environ``) lacks it, and torch's intra-op
    threads to ``OMP_NUM_THREADS`` when ``sm`` chose it; returns torch's thread count."""
    environ = os.environ if environ is None else environ
    if "OMP_NUM_THREADS" not in environ:
        torch.set_num_threads(int(DEFAULT_ENV["OMP_NUM_THREADS"]))
    for name, value in DEFAULT_ENV.items():
        environ.setdefault(name, value)
    return torch.get_num_threads()
