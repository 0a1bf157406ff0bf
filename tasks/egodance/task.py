"""EgoDance's registration (entry point ``egodance`` of ``skeleton_mamba.tasks``; torch-free)."""

from skeleton_mamba.tasks.training.registry import Command, TaskSpec

_PKG = "skeleton_mamba.tasks.egodance"
TASK = TaskSpec(
    name="egodance",
    title="EgoDance",
    package=_PKG,
    modules=(f"{_PKG}.module", f"{_PKG}.data"),
    commands={
        "make-ego": Command(
            f"{_PKG}.builder.make_ego_cli:main",
            "build EgoAIST++-style egocentric data",
            f"{_PKG}.builder.make_ego_args:build_parser",
        ),
        "dance": Command(
            f"{_PKG}.dance_cli:main",
            "estimate a dance from music and video",
            f"{_PKG}.dance_args:build_parser",
        ),
    },
    networks={"EMM": f"{_PKG}.onnx_graphs:emm_specs"},
)
