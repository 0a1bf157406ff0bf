"""The project's only use of Lightning internals, and the jsonargparse features recipes rely on.

LightningCLI writes every applied data-to-model link (``parser.link_arguments(..., apply_on="instantiate")``)
into the model's hyper-parameters, which the checkpoint stores and ``--ckpt_path`` parses back. jsonargparse
reports a link as applied even when the chosen model class has no such argument (it skips setting the value,
but lists it), so a ``batch_size`` link to a module without ``batch_size`` lands in the checkpoint and breaks
``sm test|predict --ckpt_path``; a nested target (``network.seed_frames``) on a module without ``network``
fails already at instantiation. LightningCLI builds those hyper-parameters in its private ``_InstantiatorFn``
and offers no hook to filter the links it receives, so :class:`AcceptedLinksInstantiator` subclasses it.
Everything else the project needs from LightningCLI goes through its documented hooks
(:mod:`skeleton_mamba.tasks.training.lightning_cli`).

:data:`CHECKED_LIGHTNING` names the releases this was read against; importing this module on a Lightning whose
``_InstantiatorFn`` is gone or has another signature (:func:`private_api_problems`) raises an
:class:`ImportError` saying so, rather than running without the filter.

jsonargparse is used through its public API only: ``get_loader`` / ``set_loader`` (the bounded YAML loader of
:mod:`~skeleton_mamba.tasks.training.recipe_resolution`) and the import-path policy of
``set_parsing_settings`` (:func:`import_policy`: the ``*`` deny entry and the allow-list, which recipes' class
paths go through), plus one private name to restore that policy after a command. :data:`CHECKED_JSONARGPARSE`
names the release that was read; a jsonargparse without them (:func:`jsonargparse_problems`) raises an
:class:`ImportError` here rather than importing whatever a recipe names.
"""

from __future__ import annotations

import contextlib
import inspect
from collections.abc import Iterator, Sequence

import jsonargparse
import lightning.pytorch as pl
from lightning.pytorch import LightningModule
from lightning.pytorch.cli import LightningCLI

__all__ = [
    "CHECKED_JSONARGPARSE",
    "CHECKED_LIGHTNING",
    "PRIVATE_NAMES",
    "AcceptedLinksInstantiator",
    "install_accepted_links",
    "import_policy",
    "jsonargparse_problems",
    "private_api_problems",
]

CHECKED_LIGHTNING = ("2.5.2", "2.6.6")
"""The first and last lightning releases whose ``_InstantiatorFn`` was read for this module (the same
constructor ``(cli, key)`` and call ``(class_type, *args, applied_instantiation_links, **kwargs)`` throughout,
and unchanged on Lightning's main branch of July 2026)."""

PRIVATE_NAMES = ("lightning.pytorch.cli._InstantiatorFn", "jsonargparse._common.parsing_settings")
"""The private names used here."""
_POLICY_KEYS = ("import_path_verdicts", "import_paths_enforced")

CHECKED_JSONARGPARSE = ("4.53.0",)
"""The jsonargparse releases whose ``set_parsing_settings(import_path_denylist=["*"],
import_path_allowlist=...)`` (the path checked before ``__import__`` and the object's defining module after
it, the most specific entry deciding, ``ImportDenied`` raised once any entry is set), its private
``parsing_settings`` and ``get_loader`` / ``set_loader`` were read."""


def _unsupported(reason: str) -> ImportError:
    return ImportError(
        f"lightning {pl.__version__}: {reason}; skeleton_mamba.tasks.training.lightning_compat builds on it "
        f"(checked with lightning {CHECKED_LIGHTNING[0]} to {CHECKED_LIGHTNING[1]}): install "
        f"lightning<={CHECKED_LIGHTNING[1]} or port the adapter"
    )


try:
    # Missing public API: a LightningCLI hook that sees the applied instantiation links before Lightning's
    # model instantiator stores them as hyper-parameters (it hands them to ``save_hyperparameters`` through a
    # private context variable that only ``_InstantiatorFn`` sets).
    from lightning.pytorch.cli import _InstantiatorFn
except ImportError as err:  # pragma: no cover - only on a Lightning that removed it
    raise _unsupported("lightning.pytorch.cli._InstantiatorFn is gone") from err


def private_api_problems() -> list[str]:
    """How the installed Lightning's ``_InstantiatorFn`` differs from the one read (empty: as read)."""
    problems = []
    if list(inspect.signature(_InstantiatorFn.__init__).parameters) != ["self", "cli", "key"]:
        problems.append("_InstantiatorFn(cli, key) changed its constructor")
    link_param = inspect.signature(_InstantiatorFn.__call__).parameters.get("applied_instantiation_links")
    if link_param is None or link_param.kind is not inspect.Parameter.KEYWORD_ONLY:
        problems.append("_InstantiatorFn.__call__ no longer takes applied_instantiation_links=")
    return problems


if private_api_problems():  # pragma: no cover - only on a Lightning that changed it
    raise _unsupported("; ".join(private_api_problems()))

try:
    # Missing public API: a way to remove import-path entries again (set_parsing_settings only adds them).
    from jsonargparse._common import parsing_settings as _parsing_settings
except ImportError as err:  # pragma: no cover - only on a jsonargparse that moved it
    raise ImportError(
        f"jsonargparse {jsonargparse.__version__}: jsonargparse._common.parsing_settings is gone; "
        "skeleton_mamba.tasks.training.lightning_compat was checked with jsonargparse "
        f"{CHECKED_JSONARGPARSE[0]}"
    ) from err


def jsonargparse_problems() -> list[str]:
    """How the installed jsonargparse differs from the one read for :func:`import_policy` (empty: as read)."""
    problems = []
    if "import_path_allowlist" not in inspect.signature(jsonargparse.set_parsing_settings).parameters:
        problems.append("set_parsing_settings has no import_path_allowlist")
    if not all(key in _parsing_settings for key in _POLICY_KEYS):
        problems.append(f"parsing_settings lacks {', '.join(_POLICY_KEYS)}")
    return problems


if jsonargparse_problems():
    raise ImportError(  # pragma: no cover - only on a jsonargparse older than the policy
        f"jsonargparse {jsonargparse.__version__}: {'; '.join(jsonargparse_problems())}; the import-path "
        "policy that refuses recipes' foreign class paths was checked with jsonargparse "
        f"{CHECKED_JSONARGPARSE[0]}: "
        f"install jsonargparse>={CHECKED_JSONARGPARSE[0]} or port the adapter"
    )


@contextlib.contextmanager
def import_policy(allowed: Sequence[str]) -> Iterator[None]:
    """Within the block, class paths in parsed values may name only ``allowed`` modules (and what is under
    them); the policy before it is restored after (the ``sm`` entry may run several commands in one process).

    jsonargparse's ``*`` deny entry refuses every other import path before importing it; its own deny-list
    (``os``, ``subprocess``, ``builtins.exec``, ...) keeps its entries, more specific than any module here. A
    refusal is jsonargparse's ``ImportDenied`` (an ``ImportError``) inside the parse error.
    ``set_parsing_settings`` only adds entries, so the restore goes through jsonargparse's private
    ``parsing_settings`` (:data:`PRIVATE_NAMES`).
    """
    saved = {key: _parsing_settings[key] for key in _POLICY_KEYS}
    jsonargparse.set_parsing_settings(import_path_denylist=["*"], import_path_allowlist=list(allowed))
    try:
        yield
    finally:
        _parsing_settings.update(saved)


class AcceptedLinksInstantiator(_InstantiatorFn):
    """Lightning's model instantiator, given only the linked values the model class accepts.

    A link ``model.init_args.<name>[.<field>]`` is kept when the class's ``__init__`` has ``<name>``; links
    to other components (``data.*``) pass unchanged.
    """

    def __call__(self, class_type, *args, applied_instantiation_links: dict, **kwargs):
        accepted = inspect.signature(class_type).parameters
        prefix = f"{self.key}.init_args."
        links = {
            key: value
            for key, value in applied_instantiation_links.items()
            if not key.startswith(prefix) or key[len(prefix) :].split(".")[0] in accepted
        }
        return super().__call__(class_type, *args, applied_instantiation_links=links, **kwargs)


def install_accepted_links(cli: LightningCLI) -> None:
    """Put :class:`AcceptedLinksInstantiator` in front of Lightning's model instantiator.

    Call from ``before_instantiate_classes``, which LightningCLI runs after registering its own
    instantiators; the key ``(model class, subclass mode)`` is Lightning's, so this one replaces it.
    ``ArgumentParser.add_instantiator`` is jsonargparse's (deprecated since 4.49 in favour of an
    ``instantiators`` argument to ``instantiate``, which LightningCLI does not expose: its
    ``instantiate_classes`` calls the parser itself); Lightning registers its own the same way.
    """
    cli.parser.add_instantiator(
        AcceptedLinksInstantiator(cli=cli, key="model"),
        cli.model_class or LightningModule,
        subclasses=cli.subclass_mode_model,
        prepend=True,
    )
