"""Streaming's registration (entry point ``stream`` of ``skeleton_mamba.tasks``; torch-free)."""

from skeleton_mamba.tasks.training.registry import Command, TaskSpec

_PKG = "skeleton_mamba.tasks.stream"
TASK = TaskSpec(
    name="stream",
    title="streaming",
    package=_PKG,
    modules=(f"{_PKG}.module", f"{_PKG}.data"),
    commands={
        "stream": Command(
            f"{_PKG}.stream_cli:main",
            "live music-to-dance / online recognition",
            f"{_PKG}.stream_args:build_parser",
        ),
        "export-web": Command(
            f"{_PKG}.web_export:main",
            "the streaming dancer as a static page: dances in the browser (onnxruntime-web)",
            f"{_PKG}.export_web_args:build_parser",
        ),
    },
    networks={"StreamDancer": f"{_PKG}.onnx_graphs:dancer_specs"},
)
