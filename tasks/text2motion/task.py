"""Text-to-motion's registration (entry point ``text2motion`` of ``skeleton_mamba.tasks``; torch-free)."""

from skeleton_mamba.tasks.training.registry import Command, TaskSpec

_PKG = "skeleton_mamba.tasks.text2motion"
TASK = TaskSpec(
    name="text2motion",
    title="text-to-motion",
    package=_PKG,
    modules=(f"{_PKG}.module", f"{_PKG}.data"),
    commands={
        "generate": Command(
            f"{_PKG}.generate_cli:main", "generate motion from text", f"{_PKG}.generate_args:build_parser"
        ),
        "convert": Command(
            f"{_PKG}.convert_cli:main", "HumanML3D features to joints", f"{_PKG}.convert_args:build_parser"
        ),
    },
    networks={"TextToMotionDenoiser": f"{_PKG}.onnx_graphs:text_denoiser_specs"},
)
