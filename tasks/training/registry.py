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

The registry is read once per process, on first use (never when a module is imported), and a plugin can
neither break nor hijack the built-in tasks. The built-in tasks are the entry points of this project's own
distribution (:data:`BUILTIN_DISTRIBUTION`); every other entry point is a plugin. An entry point is skipped,
with one warning line on stderr naming its distribution and entry point (``sm: warning: ...``), when

* it does not load: any exception while importing it, ``SystemExit`` included (Ctrl-C alone goes through);
* it is malformed: not a :class:`TaskSpec`, a field of the wrong type (``modules`` not a tuple of str,
  ``commands`` not a mapping of command name -> :class:`Command`, ...), or a ``name`` other than its entry
  point's;
* it collides: its task name, its package, one of its commands (a built-in ``sm`` command such as ``fit`` or
  ``recipes`` included), one of its variants (a shared command and ``--task`` value; for a plugin, a
  ``--task`` value a built-in command's own parser takes too, such as ``sm stream --task dance``) or one of
  its networks (a class name) is already another task's. The built-in tasks are read first, so of a
  built-in and a plugin the plugin is refused; of two plugins, the later in entry-point name order is
  refused, and the warning names both.

What is left is merged: the ``sm`` commands, the variants and the networks of the tasks that were kept.
"""

from __future__ import annotations

import functools
import importlib
import re
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint, distributions, entry_points

__all__ = [
    "BUILTIN_DISTRIBUTION",
    "ENTRY_POINT_GROUP",
    "Command",
    "RegistryError",
    "describe_error",
    "TaskSpec",
    "read_registry",
    "registered_tasks",
    "task_of_class_path",
    "task_packages",
]

ENTRY_POINT_GROUP = "skeleton_mamba.tasks"
"""The entry-point group every task registers in (pyproject.toml's ``[project.entry-points.<group>]``)."""
BUILTIN_DISTRIBUTION = "skeleton-mamba"
"""The distribution whose entry points are the built-in tasks (this project's ``[project] name``)."""
MAX_REASON_CHARS = 300  # an exception's text in a warning line (cut beyond)

_DOTTED = r"[^\W\d]\w*(?:\.[^\W\d]\w*)*"  # a dotted module path
_TARGET = re.compile(rf"{_DOTTED}:[^\W\d]\w*")  # "module:function"
_COMMAND_NAME = re.compile(r"[^\W_][\w.-]*")  # what ``sm NAME`` can run: no option, no space


class RegistryError(RuntimeError):
    """Why a registered entry point is not used: it does not load to a usable :class:`TaskSpec`, or part of it
    is another task's already (the warning that skips it names the entry point)."""


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
            checkpoints like the project's own, since installing the task registered it). No two tasks'
            packages may overlap.
        modules: the modules defining its LightningModule and LightningDataModule classes, imported before a
            recipe is parsed so that recipes may name those classes by their short names.
        commands: ``sm`` command name -> :class:`Command`, the task's own commands.
        variants: shared command -> {value of its ``--task`` option -> :class:`Command`}: the task's
            variant of a command another task (or the machinery) owns (``sm stream --task recognition``); a
            plugin's variant may not take a value a built-in command's own parser takes for ``--task``.
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
    """Every usable task registered in :data:`ENTRY_POINT_GROUP`, ordered by name (read once per process).

    An entry point that does not load, is malformed or collides (the module docstring's policy) is left out
    with one warning line on stderr, printed on this first read; nothing a plugin does here raises, or ends
    the process, but Ctrl-C.
    """
    points, warnings = _group_entry_points()
    specs, refusals = read_registry(points)
    for line in [*warnings, *refusals]:
        print(f"sm: warning: {line}", file=sys.stderr)
    return specs


def read_registry(points: Iterable[EntryPoint]) -> tuple[tuple[TaskSpec, ...], list[str]]:
    """The tasks of ``points`` that are usable (ordered by name) and one line per entry point refused.

    The built-in entry points (:data:`BUILTIN_DISTRIBUTION`'s) are read first, then the plugins', each group
    in entry-point name order, so that a collision refuses the plugin, or the later of two plugins. The
    specs returned are copies holding plain dicts and tuples.
    """
    taken = _Taken(_machinery_commands())
    seen: set[tuple[str | None, str, str]] = set()
    refusals: list[str] = []
    for point, distribution in sorted(
        ((point, _distribution(point)) for point in points),
        key=lambda pair: (not _is_builtin(pair[1]), pair[0].name, pair[1] or ""),
    ):
        if (distribution, point.name, point.value) in seen:  # one distribution found twice on the path
            continue
        seen.add((distribution, point.name, point.value))
        where = _describe(point, distribution)
        try:
            spec = _checked(_loaded(point), point.name)
            taken.add(spec, where, _is_builtin(distribution))
        except RegistryError as err:
            kind = "built-in task" if _is_builtin(distribution) else "task plugin"
            refusals.append(f"{kind} skipped: {where}: {err}")
    return tuple(sorted(taken.specs, key=lambda spec: spec.name)), refusals


def task_packages() -> tuple[str, ...]:
    """The import packages of the registered tasks."""
    return tuple(spec.package for spec in registered_tasks())


def task_of_class_path(class_path: str) -> TaskSpec | None:
    """The registered task whose package holds ``class_path`` (a dotted class path), else None."""
    for spec in registered_tasks():
        if class_path.startswith(spec.package + "."):
            return spec
    return None


def _group_entry_points() -> tuple[list[EntryPoint], list[str]]:
    """The entry points of :data:`ENTRY_POINT_GROUP`, and a line per distribution whose entry points cannot be
    read (a malformed ``entry_points.txt`` fails the whole query: the distributions are then read one by
    one, the first of each name only, as the query does)."""
    try:
        return list(entry_points(group=ENTRY_POINT_GROUP)), []
    except Exception:  # noqa: BLE001 (read the distributions one by one below)
        pass
    points: list[EntryPoint] = []
    problems: list[str] = []
    names: set[str] = set()
    for dist in distributions():
        name = "(unnamed)"
        try:
            name = dist.metadata["Name"] or name
            key = re.sub(r"[-_.]+", "-", name).lower()
            if key in names:
                continue
            names.add(key)
            points += dist.entry_points.select(group=ENTRY_POINT_GROUP)
        except Exception as err:  # noqa: BLE001 (the other distributions' tasks stay usable)
            problems.append(f"distribution {name}: its entry points cannot be read ({describe_error(err)})")
    return points, problems


def _distribution(point: EntryPoint) -> str | None:
    """The name of the distribution that registered ``point``, when known."""
    try:
        dist = getattr(point, "dist", None)
        name = None if dist is None else dist.name
    except Exception:  # noqa: BLE001 (unreadable metadata: an unknown distribution)
        return None
    return name if isinstance(name, str) and name else None


def _is_builtin(distribution: str | None) -> bool:
    return distribution is not None and re.sub(r"[-_.]+", "-", distribution).lower() == BUILTIN_DISTRIBUTION


def _describe(point: EntryPoint, distribution: str | None) -> str:
    return (
        f"entry point {point.name} = {point.value} "
        f"(distribution {distribution or 'unknown'}, group {ENTRY_POINT_GROUP})"
    )


def describe_error(err: BaseException) -> str:
    """``err`` as ``Type: text`` on one line, cut to :data:`MAX_REASON_CHARS`."""
    try:
        text = " ".join(str(err).split())
    except Exception:  # noqa: BLE001 (an exception whose text cannot be read)
        text = ""
    reason = f"{type(err).__name__}: {text}" if text else type(err).__name__
    return reason if len(reason) <= MAX_REASON_CHARS else reason[: MAX_REASON_CHARS - 3] + "..."


def _loaded(point: EntryPoint) -> object:
    """What ``point`` names; :class:`RegistryError` for anything raised importing it but Ctrl-C (a
    ``SystemExit`` included: a plugin never ends the process)."""
    try:
        return point.load()
    except KeyboardInterrupt:
        raise
    except BaseException as err:  # noqa: BLE001 (a plugin's failure is reported, not raised)
        raise RegistryError(f"does not load ({describe_error(err)})") from None


def _shown(value: object) -> str:
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001
        text = f"a {type(value).__name__}"
    return text if len(text) <= 60 else text[:57] + "..."


def _is_target(value: object) -> bool:
    return isinstance(value, str) and _TARGET.fullmatch(value) is not None


def _is_dotted(value: object) -> bool:
    return isinstance(value, str) and re.fullmatch(_DOTTED, value) is not None


def _is_command_name(value: object) -> bool:
    return isinstance(value, str) and _COMMAND_NAME.fullmatch(value) is not None


def _is_command(value: object) -> bool:
    return (
        isinstance(value, Command)
        and _is_target(value.run)
        and isinstance(value.help, str)
        and "\n" not in value.help
        and (value.parser is None or _is_target(value.parser))
    )


def _mapping(
    value: object, name: str, what: str, key_ok: Callable[[object], bool], value_ok: Callable[[object], bool]
) -> dict:
    """``value`` as a plain dict, checked to be a mapping of ``what``."""
    if not isinstance(value, Mapping):
        raise RegistryError(f"{name} is a {type(value).__name__}, not a mapping of {what}")
    items = dict(value.items())
    for key, item in items.items():
        if not key_ok(key) or not value_ok(item):
            raise RegistryError(f"{name} is not a mapping of {what} (at {_shown(key)}: {_shown(item)})")
    return items


def _checked(spec: object, point_name: str) -> TaskSpec:
    """A plain copy of ``spec`` checked field by field; :class:`RegistryError` says what is wrong."""
    if not isinstance(spec, TaskSpec):
        raise RegistryError(f"names a {type(spec).__name__}, not a TaskSpec")
    try:
        for attribute, ok in (("name", _is_command_name), ("title", None), ("package", _is_dotted)):
            value = getattr(spec, attribute)
            if not isinstance(value, str) or (ok is not None and not ok(value)):
                raise RegistryError(f"its {attribute} is {_shown(value)}, not a valid str")
        if spec.name != point_name:
            raise RegistryError(f"its TaskSpec is named {spec.name!r}")
        modules = spec.modules
        if not isinstance(modules, tuple) or not all(_is_dotted(module) for module in modules):
            raise RegistryError(f"its modules are {_shown(modules)}, not a tuple of module names (str)")
        commands = _mapping(spec.commands, "commands", "name -> Command", _is_command_name, _is_command)
        variants = _mapping(spec.variants, "variants", "command -> mapping", _is_command_name, _anything)
        for command, by_task in variants.items():
            name = f"variants[{command!r}]"
            variants[command] = _mapping(by_task, name, "value -> Command", _is_command_name, _is_command)
        networks = _mapping(spec.networks, "networks", "class name -> target", _is_class, _is_target)
        copy = TaskSpec(spec.name, spec.title, spec.package, modules, commands, variants, networks)
    except (RegistryError, KeyboardInterrupt):
        raise
    except BaseException as err:  # noqa: BLE001 (a field whose reading raises)
        raise RegistryError(f"its TaskSpec cannot be read ({describe_error(err)})") from None
    return copy


def _anything(value: object) -> bool:
    return True


def _is_class(value: object) -> bool:
    return isinstance(value, str) and value.isidentifier()


def _machinery_commands() -> dict[str, Command]:
    """The ``sm`` commands of the machinery and the toolkit (``fit``, ``recipes``, ...): no task takes one."""
    from skeleton_mamba.tasks.training.cli import MACHINERY_COMMANDS  # noqa: PLC0415  # lazy: cli imports this module

    return dict(MACHINERY_COMMANDS)


def _own_task_values(command: Command) -> frozenset[str]:
    """The values ``command``'s own parser takes for ``--task`` (its choices and default), empty when it has
    none: a built-in command's own modes (``sm stream --task dance``), which no plugin's variant takes."""
    try:
        if command.parser is None:
            return frozenset()
        module, function = command.parser.split(":")
        parser = getattr(importlib.import_module(module), function)()
        for action in parser._actions:
            if "--task" in action.option_strings:
                values = [*(action.choices or ()), action.default]
                return frozenset(v for v in values if isinstance(v, str))
    except KeyboardInterrupt:
        raise
    except BaseException:  # noqa: BLE001 (a parser that does not build has no --task values to protect)
        pass
    return frozenset()


class _Taken:
    """What the tasks kept so far own: names, packages, commands, variants and networks, each with its owner
    as a warning names it."""

    def __init__(self, machinery: Mapping[str, Command]) -> None:
        self.specs: list[TaskSpec] = []
        self.names: dict[str, str] = {}
        self.packages: dict[str, str] = {}
        self.commands: dict[str, tuple[str, Command, bool]] = {  # name -> (owner, command, built-in)
            name: ("a built-in sm command", command, True) for name, command in machinery.items()
        }
        self.variants: dict[tuple[str, str], str] = {}
        self.networks: dict[str, str] = {}

    def add(self, spec: TaskSpec, where: str, builtin: bool) -> None:
        """Keep ``spec``; :class:`RegistryError` naming every clash with a task kept before (nothing kept)."""
        clashes = []
        if spec.name in self.names:
            clashes.append(f"task name {spec.name!r} is taken by {self.names[spec.name]}")
        for package, owner in self.packages.items():
            if _overlap(spec.package, package):
                clashes.append(f"package {spec.package!r} overlaps {package!r} of {owner}")
        for name in spec.commands:
            if name in self.commands:
                clashes.append(f"command {name!r} is taken by {self.commands[name][0]}")
        for command, by_task in spec.variants.items():
            shared = self.commands.get(command)
            protect = not builtin and shared is not None and shared[2] and bool(by_task)
            own = _own_task_values(shared[1]) if protect else frozenset()  # a built-in command's own modes
            for value in by_task:
                variant = f"sm {command} --task {value}"
                if (command, value) in self.variants:
                    clashes.append(f"variant {variant!r} is taken by {self.variants[(command, value)]}")
                elif value in own:
                    clashes.append(f"variant {variant!r} is taken by {shared[0]}")
        for name in spec.networks:
            if name in self.networks:
                clashes.append(f"network {name!r} is taken by {self.networks[name]}")
        if clashes:
            raise RegistryError("; ".join(clashes))
        owner = f"the built-in task {spec.name!r}" if builtin else f"task {spec.name!r} ({where})"
        self.specs.append(spec)
        self.names[spec.name] = owner
        self.packages[spec.package] = owner
        self.commands.update((name, (owner, command, builtin)) for name, command in spec.commands.items())
        self.variants.update(((c, v), owner) for c, by_task in spec.variants.items() for v in by_task)
        self.networks.update((name, owner) for name in spec.networks)


def _overlap(package: str, other: str) -> bool:
    return package == other or package.startswith(other + ".") or other.startswith(package + ".")
