"""QEAN's registration (entry point ``qean`` of ``skeleton_mamba.tasks``; torch-free).

QEAN has no command of its own (``sm fit|test|predict`` run it) and exports its backbone."""

from skeleton_mamba.tasks.training.registry import TaskSpec

_PKG = "skeleton_mamba.tasks.qean"
TASK = TaskSpec(
    name="qean",
    title="QEAN",
    package=_PKG,
    modules=(f"{_PKG}.module", f"{_PKG}.data"),
)
