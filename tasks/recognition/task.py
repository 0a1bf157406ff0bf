"""Action recognition's registration (entry point ``recognition`` of ``skeleton_mamba.tasks``; torch-free)."""

from skeleton_mamba.tasks.training.registry import Command, TaskSpec

_PKG = "skeleton_mamba.tasks.recognition"
TASK = TaskSpec(
    name="recognition",
    title="recognition",
    package=_PKG,
    modules=(f"{_PKG}.module", f"{_PKG}.data"),
    commands={
        "prepare": Command(
            f"{_PKG}.prepare:main",
            "build NTU / Kinetics annotation files",
            f"{_PKG}.prepare_args:build_parser",
        ),
        "ensemble": Command(
            f"{_PKG}.ensemble:main",
            "add the test scores of several recognition streams (PYSKL)",
            f"{_PKG}.ensemble_args:build_parser",
        ),
    },
    variants={
        "stream": {
            "recognition": Command(
                f"{_PKG}.online:main", "online action recognition", f"{_PKG}.online_args:build_parser"
            ),
        },
    },
    networks={"ActionRecognizer": f"{_PKG}.onnx_graphs:recognizer_specs"},
)
