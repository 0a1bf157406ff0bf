"""Registries of the things users add, in the shape of mmengine's: a name -> object table that is filled
where each object is defined.

Two ways in, both one line:

- **where it is defined**: ``@MOTION_FORMATS.register("bvh")`` above the object, in a module the registry's
  ``locations`` list (imported on the first lookup, as mmengine's ``locations``), or in any module the
  user imports before the lookup (a script, a notebook);
- **by an entry point**, when the names must be known without importing the objects (``sm CMD --help``
  lists the samplers without importing torch): a line of ``pyproject.toml``'s
  ``[project.entry-points."<group>"]`` naming the object, here or in another distribution; the object is
  imported on its first :meth:`Registry.get`.

Standard library only, so the torch-free ``--help`` paths can read a registry's :meth:`~Registry.names`.

Examples:
    >>> COLOURS = Registry("colour")
    >>> @COLOURS.register("red")
    ... def red() -> tuple[int, int, int]:
    ...     return (255, 0, 0)
    >>> COLOURS.names(), COLOURS.get("red")()
    (('red',), (255, 0, 0))
    >>> try:
    ...     COLOURS.get("blue")
    ... except UnknownNameError as err:  # a KeyError and a ValueError
    ...     print(err)
    colour must be one of red, got 'blue'
"""

from __future__ import annotations

import importlib
import threading
from collections.abc import Callable, Iterable
from importlib.metadata import entry_points
from typing import Generic, TypeVar

__all__ = ["Registry", "UnknownNameError"]

T = TypeVar("T")


class UnknownNameError(KeyError, ValueError):
    """A name no object is registered under (a ``KeyError`` for mappings, a ``ValueError`` for options); the
    message lists the registered names."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class _EntryPoint(str):
    """An entry point's ``"module:attribute"``, registered but not imported yet."""


class Registry(Generic[T]):
    """A table of named objects of one kind (a sampler, a motion format).

    Args:
        kind: what is registered, for messages (``"sampler"``).
        locations: modules imported on the first lookup, whose decorators register the built-in objects.
        group: an entry-point group whose names are registered without importing them (the object loads
            on its first :meth:`get`).
    """

    def __init__(self, kind: str, locations: Iterable[str] = (), group: str | None = None) -> None:
        self.kind = kind
        self.locations = tuple(locations)
        self.group = group
        self._entries: dict[str, T | _EntryPoint] = {}  # in registration order; entry points until loaded
        self._filled = False
        self._lock = threading.RLock()

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, names={self.names()!r})"

    def register(self, name: str, *, force: bool = False) -> Callable[[T], T]:
        """A decorator registering its object under ``name`` and returning it unchanged.

        Raises:
            ValueError: ``name`` is empty, or taken by another object and ``force`` is False.
        """
        if not isinstance(name, str) or not name:
            raise ValueError(f"a {self.kind} needs a non-empty name, got {name!r}")

        def add(obj: T) -> T:
            with self._lock:
                taken = self._entries.get(name)
                if (
                    taken is not None
                    and taken is not obj
                    and not force
                    and not isinstance(taken, _EntryPoint)
                ):
                    raise ValueError(f"{self.kind} {name!r} is registered already ({taken!r})")
                self._entries[name] = obj
            return obj

        return add

    def unregister(self, name: str) -> None:
        """Remove ``name`` (a ``KeyError`` when it is not registered): a test's or a notebook's own entry."""
        self._fill()
        with self._lock:
            if self._entries.pop(name, None) is None:
                raise KeyError(f"no {self.kind} {name!r} is registered")

    def _fill(self) -> None:
        """Read the entry points' names and import the locations, once."""
        with self._lock:
            if self._filled:
                return
            self._filled = True
            if self.group is not None:
                for point in sorted(entry_points(group=self.group), key=lambda p: p.name):
                    self._entries.setdefault(point.name, _EntryPoint(point.value))
            for module in self.locations:
                importlib.import_module(module)

    def names(self) -> tuple[str, ...]:
        """Every registered name, in the order each was first registered (the entry points' in name order)."""
        self._fill()
        with self._lock:
            return tuple(self._entries)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self.names()

    def get(self, name: str) -> T:
        """The object registered under ``name`` (an entry point's is imported now).

        Raises:
            UnknownNameError: no object has that name; the message lists the names.
        """
        self._fill()
        with self._lock:
            entry = self._entries.get(name)
            if entry is None:
                known = ", ".join(self._entries) or "none is registered"
                raise UnknownNameError(f"{self.kind} must be one of {known}, got {name!r}")
            if not isinstance(entry, _EntryPoint):
                return entry
            module, _, attribute = entry.partition(":")
            obj = getattr(importlib.import_module(module), attribute) if attribute else None
            if obj is None:
                raise ValueError(f"{self.kind} {name!r}: entry point {entry!r} names no object")
            self._entries[name] = obj
            return obj
