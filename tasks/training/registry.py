"""The task registry: every task declares itself once, in its own folder, and is found by its entry point.

A task is a package (``tasks/<name>/`` here, or any installed distribution) with a torch-free module, by
convention ``task.py``, that holds one :class:`TaskSpec`: its name as the docs write it, the modules of its
LightningModule and LightningDataModule classes (a data module names its typed contract itself:
``contract_class``), its ``sm`` commands and its variants of shared commands, and its exportable networks. The
package's ``pyproject.toml`` names that object in the entry-point group :data:`ENTRY_POINT_GROUP`::

    [project.entry-points."skeleton_mamba.tasks"]
    gesture = "gesture_task.task:TASK"

and the machinery (``tasks/training/``) reads every registered task through :func:`registered_tasks`; it
names no task itself. Everything in a spec is a string (``"module:function"`` or a dotted class path) and is
imported only where it is used, so ``sm --help`` reads the registry without torch or Lightning.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points

__all__ = [
    "ENTRY_POINT_GROUP",
    "Command",
    "RegistryError",
    "TaskSpec",
    "registered_tasks",
    "task_of_class_path",
    "task_packages",
]

ENTRY_POINT_GROUP = "skeleton_mamba.tasks"
"""The entry-point group every task registers in (pyproject.toml's ``[project.entry-points.<group>]``)."""


class RegistryError(RuntimeError):
    """A registered entry point that is not a usable :class:`TaskSpec` (named in the message)."""


@dataclass(frozen=True)
class Command:
    """One ``sm`` command.

    ``run``: ``"module:function"``, imported only to run; the function takes the arguments after the command
    name (the LightningCLI entry also receives the subcommand) and returns an exit code. ``help``: one line
    for ``sm --help``. ``parser``: ``"module:function"`` returning the command's argparse parser from a
    module that imports no torch (the same parser ``run`` parses with); None for the LightningCLI commands,
    whose parser is Lightning's.
    """

    run: str
    help: str
    parser: str | None = None


@dataclass(frozen=True)
class TaskSpec:
    """What the machinery needs from one task, declared in the task's own folder.

    Attributes:
        name: the task's short name (its entry point's name; its folder's for the tasks of this repository).
        title: the task's name as the docs write it (``"EgoDance"``, ``"text-to-motion"``): messages such as
            "this is an EgoDance checkpoint, not a QEAN one" use it.
        package: the task's import package; class paths under it are the task's (trusted in recipes and
            checkpoints like the project's own, since installing the task registered it).
        modules: the modules defining its LightningModule and LightningDataModule classes, imported before a
            recipe is parsed so that recipes may name those classes by their short names.
        commands: ``sm`` command name -> :class:`Command`, the task's own commands.
        variants: shared command -> {value of its ``--task`` option -> :class:`Command`}: the task's
            variant of a command another task (or the machinery) owns (``sm stream --task recognition``).
        networks: task network class name -> ``"module:function"`` returning its ONNX graphs
            (``function(network, frames=...) -> {graph name: ExportSpec}``, see
            :mod:`~skeleton_mamba.tasks.training.onnx_graphs`); a network not named exports its backbone.
    """

    name: str
    title: str
    package: str
    modules: tuple[str, ...] = ()
    commands: Mapping[str, Command] = field(default_factory=dict)
    variants: Mapping[str, Mapping[str, Command]] = field(default_factory=dict)
    networks: Mapping[str, str] = field(default_factory=dict)


@functools.cache
def registered_tasks() -> tuple[TaskSpec, ...]:
    """Every task registered in :data:`ENTRY_POINT_GROUP`, ordered by name (read once per process).

    Raises:
        RegistryError: an entry point that does not load to a :class:`TaskSpec`, whose ``name`` differs from
            the entry point's, or two tasks of one name or command.
    """
    specs: dict[str, TaskSpec] = {}
    commands: dict[str, str] = {}
    for point in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda p: p.name):
        where = f"entry point {point.name} = {point.value} ({ENTRY_POINT_GROUP})"
        try:
            spec = point.load()
        except (ImportError, AttributeError) as err:
            raise RegistryError(f"{where}: does not load ({err})") from err
        if not isinstance(spec, TaskSpec):
            raise RegistryError(f"{where}: names a {type(spec).__name__}, not a TaskSpec")
        if spec.name != point.name:
            raise RegistryError(f"{where}: its TaskSpec is named {spec.name!r}")
        if spec.name in specs:
            if specs[spec.name] == spec:  # the same distribution found twice on the path
                continue
            raise RegistryError(f"{where}: a second task named {spec.name!r}")
        for command in spec.commands:
            if command in commands:
                raise RegistryError(f"{where}: command {command!r} is task {commands[command]!r}'s already")
            commands[command] = spec.name
        specs[spec.name] = spec
    return tuple(specs.values())


def task_packages() -> tuple[str, ...]:
    """The import packages of the registered tasks."""
    return tuple(spec.package for spec in registered_tasks())


def task_of_class_path(class_path: str) -> TaskSpec | None:
    """The registered task whose package holds ``class_path`` (a dotted class path), else None."""
    for spec in registered_tasks():
        if class_path.startswith(spec.package + "."):
            return spec
    return None
