"""``sm``: the Skeleton Mamba command line, its command table and its error policy.

``sm fit|validate|test|predict --recipe NAME`` runs LightningCLI (:mod:`.lightning_cli`); the helper
commands (``sm prepare``, ``sm analyze-music``, ``sm render``, ...) live beside the task or toolkit code
that implements them and are named here as strings, imported only when their command runs (lazy for
start-up time: ``sm --help`` imports neither Lightning nor a task). Every command shares one error policy:
an expected failure (:func:`~skeleton_mamba.tasks.motion.errors.expected_failure`) prints one line
``sm COMMAND: error: MESSAGE`` (argparse's own form for a bad argument, so every refusal reads alike) and
exits 2, Ctrl-C prints one line and exits 130, anything else keeps its traceback. The commands raise; they
print no error line of their own.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
import warnings
from collections.abc import Sequence

from skeleton_mamba import __version__
from skeleton_mamba.tasks.motion.errors import expected_failure, one_line_message
from skeleton_mamba.tasks.training.allocator import keep_freed_memory
from skeleton_mamba.tasks.training.threads import apply_thread_defaults

# name -> ("module:function", one-line help). Each function takes the arguments after the
# command name (the LightningCLI entry also receives the subcommand) and returns an exit code.
COMMANDS: dict[str, tuple[str, str]] = {
    "fit": ("skeleton_mamba.tasks.training.lightning_cli:run", "train a model from a recipe (LightningCLI)"),
    "validate": ("skeleton_mamba.tasks.training.lightning_cli:run", "run the validation loop of a recipe"),
    "test": ("skeleton_mamba.tasks.training.lightning_cli:run", "evaluate a checkpoint on the test split"),
    "predict": ("skeleton_mamba.tasks.training.lightning_cli:run", "run a recipe's prediction loop"),
    "recipes": ("skeleton_mamba.tasks.training.lightning_cli:list_recipes", "list the packaged recipes"),
    "prepare": ("skeleton_mamba.tasks.recognition.prepare:main", "build NTU / Kinetics annotation files"),
    "analyze-music": (
        "skeleton_mamba.tasks.motion.analyze_music:main",
        "tempo, beats and features of a track",
    ),
    "evaluate-dance": ("skeleton_mamba.tasks.motion.evaluate_dance:main", "dance metrics, paper protocols"),
    "render": ("skeleton_mamba.tasks.motion.render_cli:main", "render a motion file to mp4 / gif"),
    "export": ("skeleton_mamba.tasks.motion.export_cli:main", "write a motion file as glTF 2.0 (.glb)"),
    "view": ("skeleton_mamba.tasks.motion.view:main", "motions in one self-contained HTML viewer"),
    "stream": ("skeleton_mamba.tasks.stream.cli:main", "live music-to-dance / online recognition"),
    "make-ego": ("skeleton_mamba.tasks.egodance.builder.cli:main", "build EgoAIST++-style egocentric data"),
    "dance": ("skeleton_mamba.tasks.egodance.dance_cli:main", "estimate a dance from music and video"),
    "generate": ("skeleton_mamba.tasks.text2motion.generate_cli:main", "generate motion from text"),
    "export-onnx": (
        "skeleton_mamba.tasks.training.onnx_export:main",
        "a backbone or task network as ONNX (sequence forward, streaming step)",
    ),
    "convert": ("skeleton_mamba.tasks.text2motion.convert_cli:main", "HumanML3D features to joints"),
    "export-pretrained": (
        "skeleton_mamba.tasks.training.export_pretrained:main",
        "a checkpoint as a Hugging Face from_pretrained folder",
    ),
}
# command -> {value of its --task option: "module:function"}: a task's own variant of a shared command
TASK_VARIANTS: dict[str, dict[str, str]] = {
    "stream": {"recognition": "skeleton_mamba.tasks.recognition.online:main"},
}
LIGHTNING_SUBCOMMANDS = ("fit", "validate", "test", "predict")
EXIT_BAD_INPUT = 2  # an expected failure: bad or missing input, unwritable output (one line, no traceback)
EXIT_INTERRUPTED = 130  # Ctrl-C (128 + SIGINT), as shells report it


def _module_available(target: str) -> bool:
    module = target.split(":")[0]
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def available_commands() -> dict[str, tuple[str, str]]:
    """The commands whose implementation is installed."""
    return {name: spec for name, spec in COMMANDS.items() if _module_available(spec[0])}


def _usage() -> str:
    lines = [
        f"sm {__version__}: Skeleton Mamba command line",
        "",
        "usage: sm COMMAND [ARGS...]        (sm COMMAND --help for its options)",
        "       sm fit --recipe ntu60.yaml [--config more.yaml] [--trainer.max_epochs 3 ...]",
        "",
        "commands:",
    ]
    for name, (_, help_text) in available_commands().items():
        lines.append(f"  {name:<15}{help_text}")
    lines += ["", "options:", "  -h, --help     show this message", "  --version      print the version"]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sm`` console script; returns the exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(_usage())
        return 0
    if args[0] in ("-V", "--version"):
        print(f"skeleton-mamba {__version__}")
        return 0
    command, rest = args[0], args[1:]
    commands = available_commands()
    if command not in commands:
        print(f"sm: unknown command {command!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    apply_thread_defaults()  # one intra-op thread on a small machine unless OMP_NUM_THREADS is set
    silence_library_deprecations()
    module_name, func_name = _target(command, rest, commands[command][0]).split(":")
    if command in LIGHTNING_SUBCOMMANDS:
        keep_freed_memory()  # the next step reuses what this one freed, instead of faulting in new pages
        rest = [command, *rest]
    try:
        func = getattr(importlib.import_module(module_name), func_name)
        result = func(rest)
    except KeyboardInterrupt:
        print(f"sm {command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as err:
        message = _expected_failure_message(err)
        if message is None or os.environ.get("SM_TRACEBACK"):
            raise
        print(error_line(command, message), file=sys.stderr)
        return EXIT_BAD_INPUT
    return int(result or 0)


def error_line(command: str, message: str) -> str:
    """The line ``sm`` prints for an expected failure of ``command``: argparse's ``prog: error: message``."""
    return f"sm {command}: error: {message}"


# Warnings a library raises about its own use of another library's API: nothing a user of `sm` can act on.
# (message, category, module) as for warnings.filterwarnings; each names the versions it was seen with.
LIBRARY_DEPRECATIONS = (
    # lightning 2.6.6 (utilities/_pytree.py) with torch 2.13, on every fit
    (
        r"`isinstance\(treespec, LeafSpec\)` is deprecated",
        FutureWarning,
        r"lightning\.pytorch\.utilities\._pytree",
    ),
)


def silence_library_deprecations() -> None:
    """Ignore :data:`LIBRARY_DEPRECATIONS` (only those: every other warning still shows)."""
    for message, category, module in LIBRARY_DEPRECATIONS:
        warnings.filterwarnings("ignore", message=message, category=category, module=module)


def _target(command: str, args: list[str], default: str) -> str:
    """The function that runs ``command``: its ``--task`` variant when it has one (:data:`TASK_VARIANTS`)."""
    variants = TASK_VARIANTS.get(command, {})
    for i, arg in enumerate(args):
        value = arg.split("=", 1)[1] if arg.startswith("--task=") else None
        if arg == "--task" and i + 1 < len(args):
            value = args[i + 1]
        if value is not None:
            return variants.get(value, default)
    return default


def _expected_failure_message(err: BaseException) -> str | None:
    """The one-line message for an expected failure (bad input, missing or unwritable path); else None."""
    failure = expected_failure(err)
    return None if failure is None else one_line_message(failure)


if __name__ == "__main__":
    sys.exit(main())
