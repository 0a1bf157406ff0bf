"""The data-to-model links, derived from the two classes: a contract's fields and the model's arguments.

A data module's contract (:class:`~skeleton_mamba.tasks.training.base_data.DataContract`) names each value the
data fixes; the model takes it as the constructor argument of the same name (``num_classes``), or as the field
of that name of one of its config-dataclass arguments (``network.music_dim``). The links are read off the two
classes, so nothing lists them, and a contract field the model takes nowhere (a misspelt name, a data module
paired with another task's model) is refused before anything is built, in one line."""

from __future__ import annotations

import dataclasses
import inspect
import types
import typing

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.training.base_data import DataContract, linked_fields

__all__ = ["contract_class_of", "contract_links"]


def contract_class_of(data_class: type) -> type[DataContract] | None:
    """The contract class a data-module class declares (its ``contract_class``), else None."""
    declared = getattr(data_class, "contract_class", None)
    if isinstance(declared, type) and issubclass(declared, DataContract):
        return declared
    return None


def _dataclass_types(hint: object) -> list[type]:
    """The dataclasses in a type hint (``EMMConfig``, ``EMMConfig | None``)."""
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return [hint]
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return [t for arg in typing.get_args(hint) for t in _dataclass_types(arg)]
    return []


def _config_arguments(model_class: type) -> dict[str, set[str]]:
    """Argument name -> field names, for each argument of ``model_class`` typed as a config dataclass."""
    try:
        hints = typing.get_type_hints(model_class.__init__)
    except (NameError, TypeError):  # an annotation that does not resolve: no nested targets
        return {}
    return {
        name: {f.name for t in _dataclass_types(hint) for f in dataclasses.fields(t)}
        for name, hint in hints.items()
        if _dataclass_types(hint)
    }


def contract_links(contract_class: type[DataContract], model_class: type) -> list[tuple[str, str]]:
    """(contract field, model argument or ``argument.field``) for each linked field of ``contract_class``.

    Raises:
        InputError: a linked field that ``model_class`` takes neither as an argument nor as the field of one
            config argument (or of several: ambiguous), naming the field and both classes.
    """
    parameters = set(inspect.signature(model_class).parameters)
    nested = {arg: names for arg, names in _config_arguments(model_class).items() if arg in parameters}
    links = []
    for name in linked_fields(contract_class):
        if name in parameters:
            links.append((name, name))
            continue
        owners = [arg for arg, names in nested.items() if name in names]
        if len(owners) != 1:
            field = f"{contract_class.__name__}.{name} (the data's)"
            where = (
                f"is a field of several config arguments of {model_class.__name__} ({', '.join(owners)})"
                if owners
                else f"is no argument of {model_class.__name__} nor a field of its config arguments"
            )
            raise InputError(
                f"{field} {where}: name the contract field after the argument it sets, or mark it unlinked()"
            )
        links.append((name, f"{owners[0]}.{name}"))
    return links
