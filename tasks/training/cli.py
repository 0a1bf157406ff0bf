"""``sm``: the Skeleton Mamba command line, its command table and its error policy.

``sm fit|validate|test|predict --recipe NAME`` runs LightningCLI (:mod:`.lightning_cli`); the helper
commands (``sm analyze-music``, ``sm render``, ...) live beside the toolkit or machinery code that
implements them and are named here as strings; a task's commands (``sm prepare``, ``sm dance``, ...) and its
variants of shared ones come from its registration (:mod:`.registry`: the task's ``TaskSpec``, found by its
entry point), so this module names no task. The registry is read when :func:`main` first needs the command
table, not when this module is imported: a plugin that is broken or takes a built-in's name is left out
with one warning line, and the built-in commands keep working. A command is imported only when it runs,
and its parser comes from a module that imports no torch (``*_args.py`` beside it, with the shared options of
:mod:`~skeleton_mamba.tasks.motion.commands.cli_options`): ``sm`` parses the command line with it first, so
``sm --help``, ``sm CMD --help``, a bad argument or a missing input file answer before torch, Lightning or
a checkpoint loads (``benchmarks/bench_startup.py`` times them).
Every command shares one error policy:
an expected failure (:func:`~skeleton_mamba.errors.expected_failure`) prints one line
``sm COMMAND: error: MESSAGE`` (argparse's own form for a bad argument, so every refusal reads alike) and
exits 2, Ctrl-C prints one line and exits 130, anything else keeps its traceback. The commands raise; they
print no error line of their own.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import os
import sys
from collections.abc import Callable, Sequence

from skeleton_mamba import __version__
from skeleton_mamba.errors import expected_failure, one_line_message
from skeleton_mamba.runtime.allocator import keep_freed_memory
from skeleton_mamba.tasks.training.library_noise import silence_library_noise
from skeleton_mamba.tasks.training.registry import Command, registered_tasks
from skeleton_mamba.tasks.training.threads import apply_thread_defaults

_PKG = "skeleton_mamba.tasks"
_LIGHTNING = f"{_PKG}.training.lightning_cli:run"
MACHINERY_COMMANDS: dict[str, Command] = {
    "fit": Command(_LIGHTNING, "train a model from a recipe (LightningCLI)"),
    "validate": Command(_LIGHTNING, "run the validation loop of a recipe"),
    "test": Command(_LIGHTNING, "evaluate a checkpoint on the test split"),
    "predict": Command(_LIGHTNING, "run a recipe's prediction loop"),
    "recipes": Command(
        f"{_PKG}.training.recipes_cli:main",
        "list the packaged recipes",
        f"{_PKG}.training.recipes_args:build_parser",
    ),
    "analyze-music": Command(
        f"{_PKG}.motion.commands.analyze_music:main",
        "tempo, beats and features of a track",
        f"{_PKG}.motion.commands.analyze_music_args:build_parser",
    ),
    "evaluate-dance": Command(
        f"{_PKG}.motion.commands.evaluate_dance:main",
        "dance metrics, paper protocols",
        f"{_PKG}.motion.commands.evaluate_dance_args:build_parser",
    ),
    "render": Command(
        f"{_PKG}.motion.commands.render_cli:main",
        "render a motion file to mp4 / gif",
        f"{_PKG}.motion.commands.render_args:build_parser",
    ),
    "export": Command(
        f"{_PKG}.motion.commands.export_cli:main",
        "write a motion file as glTF 2.0 (.glb)",
        f"{_PKG}.motion.commands.export_args:build_parser",
    ),
    "retarget": Command(
        f"{_PKG}.motion.commands.retarget_cli:main",
        "put a motion on your character (skinned glTF, VRM or BVH rig)",
        f"{_PKG}.motion.commands.retarget_args:build_parser",
    ),
    "view": Command(
        f"{_PKG}.motion.render.view:main",
        "motions in one self-contained HTML viewer",
        f"{_PKG}.motion.commands.view_args:build_parser",
    ),
    "export-onnx": Command(
        f"{_PKG}.training.onnx_export:main",
        "a backbone or task network as ONNX (sequence forward, streaming step)",
        f"{_PKG}.training.export_onnx_args:build_parser",
    ),
    "export-pretrained": Command(
        f"{_PKG}.training.export_pretrained:main",
        "a checkpoint as a Hugging Face from_pretrained folder",
        f"{_PKG}.training.export_pretrained_args:build_parser",
    ),
}
"""The commands of the machinery and the toolkit; the tasks' own come from their registrations."""


@functools.cache
def command_table() -> tuple[dict[str, Command], dict[str, dict[str, Command]]]:
    """Every ``sm`` command (the machinery's, then the registered tasks'), and command -> {value of its
    ``--task`` option: Command}, the tasks' variants of shared commands (:attr:`.registry.TaskSpec.variants`).

    Read on first use, not when this module is imported, so that reading the registry happens inside
    :func:`main`; a task that is broken or collides with another's command, variant or network is left out
    there with a warning (:func:`~.registry.registered_tasks`).
    """
    commands: dict[str, Command] = dict(MACHINERY_COMMANDS)
    variants: dict[str, dict[str, Command]] = {}
    for spec in registered_tasks():
        commands.update(spec.commands)
        for name, by_task in spec.variants.items():
            variants.setdefault(name, {}).update(by_task)
    return commands, variants


def __getattr__(name: str) -> dict:
    """``COMMANDS``: every ``sm`` command; ``TASK_VARIANTS``: the tasks' variants (:func:`command_table`,
    read on first use)."""
    if name == "COMMANDS":
        return command_table()[0]
    if name == "TASK_VARIANTS":
        return command_table()[1]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


LIGHTNING_SUBCOMMANDS = ("fit", "validate", "test", "predict")
# What ``pip install skeleton-mamba`` leaves out (pyproject.toml's extras): the import names ``sm`` checks
# (without importing them) before any command, and those of the commands that need another extra.
TASKS_EXTRA_MODULES = (
    "lightning",
    "jsonargparse",
    "torchmetrics",
    "transformers",
    "diffusers",
    "librosa",
    "soundfile",
    "trimesh",
    "kornia",
    "numpy",
    "scipy",
    "matplotlib",
    "imageio",
    "imageio_ffmpeg",
    "cv2",
    "tensorboard",
    "tqdm",
    "pygltflib",
)
COMMAND_EXTRAS = {"export-onnx": ("export", ("onnx", "onnxscript", "onnxruntime"))}
EXIT_BAD_INPUT = 2  # an expected failure: bad or missing input, unwritable output (one line, no traceback)
EXIT_INTERRUPTED = 130  # Ctrl-C (128 + SIGINT), as shells report it


def _module_available(target: str) -> bool:
    module = target.split(":")[0]
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def missing_extra(extra: str, modules: Sequence[str]) -> str | None:
    """The line telling the user to install ``extra`` when one of ``modules`` is not installed, else None."""
    missing = [name for name in modules if not _module_available(name)]
    if not missing:
        return None
    names = ", ".join(missing)
    return f'needs the [{extra}] extra (not installed: {names}): pip install "skeleton-mamba[{extra}]"'


def available_commands() -> dict[str, Command]:
    """The commands whose implementation is installed."""
    return {name: command for name, command in command_table()[0].items() if _module_available(command.run)}


def _usage() -> str:
    commands = available_commands()
    width = max(len(name) for name in commands) + 2  # the longest name and two spaces before its help
    lines = [
        f"sm {__version__}: Skeleton Mamba command line",
        "",
        "usage: sm COMMAND [ARGS...]        (sm COMMAND --help for its options)",
        "       sm fit --recipe ntu60.yaml [--config more.yaml] [--trainer.max_epochs 3 ...]",
        "",
        "commands:",
    ]
    lines += [f"  {name:<{width}}{command.help}" for name, command in commands.items()]
    lines += ["", "options:", "  -h, --help     show this message", "  --version      print the version"]
    return "\n".join(lines)


def _load(target: str) -> Callable:
    module, function = target.split(":")
    return getattr(importlib.import_module(module), function)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sm`` console script; returns the exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] in (["-V"], ["--version"]):
        print(f"skeleton-mamba {__version__}")
        return 0
    hint = missing_extra("tasks", TASKS_EXTRA_MODULES)  # the core install: the backbone without the tasks
    if hint is not None:
        print(f"sm: {hint}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        commands = available_commands()  # reads the task registry (a broken plugin: a warning, left out)
    except KeyboardInterrupt:
        print("sm: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    if not args or args[0] in ("-h", "--help"):
        print(_usage())
        return 0
    command_name, rest = args[0], args[1:]
    if command_name not in commands:
        print(f"sm: unknown command {command_name!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    extra, modules = COMMAND_EXTRAS.get(command_name, ("", ()))
    hint = missing_extra(extra, modules)
    if hint is not None:
        print(error_line(command_name, hint), file=sys.stderr)
        return EXIT_BAD_INPUT
    apply_thread_defaults()  # one intra-op thread on a small machine unless OMP_NUM_THREADS is set
    silence_library_noise()
    command = _variant(command_name, rest, commands[command_name])
    if command_name in LIGHTNING_SUBCOMMANDS:
        keep_freed_memory()  # the next step reuses what this one freed, instead of faulting in new pages
        rest = [command_name, *rest]
    try:
        if (
            command.parser is not None
        ):  # --help, a bad argument, a missing input: before the command's imports
            _load(command.parser)().parse_args(rest)
        result = _load(command.run)(rest)
    except KeyboardInterrupt:
        print(f"sm {command_name}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as err:
        message = _expected_failure_message(err)
        if message is None or os.environ.get("SM_TRACEBACK"):
            raise
        print(error_line(command_name, message), file=sys.stderr)
        return EXIT_BAD_INPUT
    return int(result or 0)


def error_line(command: str, message: str) -> str:
    """The line ``sm`` prints for an expected failure of ``command``: argparse's ``prog: error: message``."""
    return f"sm {command}: error: {message}"


def _variant(name: str, args: list[str], default: Command) -> Command:
    """The command that runs ``name``: its ``--task`` variant when it has one (:func:`command_table`)."""
    variants = command_table()[1].get(name, {})
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
