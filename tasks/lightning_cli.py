"""``sm fit|validate|test|predict`` (LightningCLI) and ``sm recipes``.

A recipe composes a task's LightningModule and LightningDataModule through ``class_path`` /
``init_args`` (subclass mode for both), so any task runs through the same CLI::

    sm fit --recipe ntu60.yaml                          # packaged recipe (see `sm recipes`)
    sm fit --recipe my.yaml --config more.yaml --trainer.max_epochs 3 --data.init_args.root data/
    sm test --recipe ntu60.yaml --ckpt_path runs/ntu60_xsub/version_0/checkpoints/last.ckpt
    sm fit --recipe ntu60.yaml --print_config

``--recipe`` is an alias of ``-c/--config`` (:mod:`skeleton_mamba.tasks.recipe_resolution`);
config files and dotted overrides merge left to right. Values that follow from the data set are
linked from the instantiated data module to the model (:data:`DATA_TO_MODEL_LINKS`), never typed
twice; a link applies when both the data module has the attribute and the model the argument.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
from collections.abc import Sequence

import lightning.pytorch as pl
from lightning.pytorch import LightningDataModule, LightningModule
from lightning.pytorch.cli import LightningArgumentParser, LightningCLI, _get_module_type, _InstantiatorFn

from skeleton_mamba import __version__
from skeleton_mamba.tasks.errors import DatasetNotFoundError
from skeleton_mamba.tasks.recipe_resolution import RecipeConfigAction, packaged_recipes, recipe_description

__all__ = ["DATA_TO_MODEL_LINKS", "SkeletonMambaCLI", "import_task_modules", "list_recipes", "run"]

# Task packages whose ``module`` and ``data`` modules are imported before parsing, so recipes may
# use short class names (``class_path: ActionRecognitionModule``).
TASK_PACKAGES = ("recognition", "egodance", "qean", "text2motion", "stream")

# data-module attribute -> model init argument, applied once the data module is instantiated.
# Linked arguments are not user-settable (jsonargparse overwrites them); set them on the data module.
DATA_TO_MODEL_LINKS: tuple[tuple[str, str], ...] = (
    ("num_classes", "num_classes"),
    ("skeleton", "skeleton"),
    ("in_channels", "in_channels"),
    ("batch_size", "batch_size"),
)


def _module_exists(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:
        return False


def import_task_modules() -> list[str]:
    """Import every installed task's ``module`` and ``data`` modules; returns their names."""
    imported = []
    for task in TASK_PACKAGES:
        for part in ("module", "data"):
            name = f"skeleton_mamba.tasks.{task}.{part}"
            if _module_exists(name):
                importlib.import_module(name)
                imported.append(name)
    return imported


class _AcceptedLinksInstantiator(_InstantiatorFn):
    """Lightning's model instantiator, recording only the linked values the model accepts.

    Lightning stores every applied data-to-model link in the checkpoint's hyper-parameters and parses them
    back on ``--ckpt_path``; a link the model has no argument for (``batch_size`` on a module without one)
    would then break ``sm test/predict --ckpt_path``.
    """

    def __call__(self, class_type, *args, applied_instantiation_links: dict, **kwargs):
        accepted = inspect.signature(class_type).parameters
        links = {
            key: value
            for key, value in applied_instantiation_links.items()
            if not key.startswith("model.") or key.rsplit(".", 1)[-1] in accepted
        }
        return super().__call__(class_type, *args, applied_instantiation_links=links, **kwargs)


class SkeletonMambaCLI(LightningCLI):
    """LightningCLI with ``--recipe`` and the data-to-model links of :data:`DATA_TO_MODEL_LINKS`."""

    def init_parser(self, **kwargs) -> LightningArgumentParser:
        """The base parser, with one config action answering to ``-c``, ``--config`` and ``--recipe``."""
        kwargs.setdefault(
            "dump_header", [f"skeleton_mamba=={__version__}", f"lightning.pytorch=={pl.__version__}"]
        )
        parser = self.parser_class(**kwargs)
        parser.add_argument(
            "-c",
            "--config",
            "--recipe",
            action=RecipeConfigAction,
            help="A recipe: a packaged name (`sm recipes` lists them) or a YAML path. Repeatable; "
            "later files and dotted options override earlier ones.",
        )
        return parser

    def add_arguments_to_parser(self, parser: LightningArgumentParser) -> None:
        for source, target in DATA_TO_MODEL_LINKS:
            parser.link_arguments(f"data.{source}", f"model.init_args.{target}", apply_on="instantiate")

    def _add_instantiators(self) -> None:
        """Lightning's instantiators, with the model's filtered by :class:`_AcceptedLinksInstantiator`."""
        super()._add_instantiators()
        self.parser.add_instantiator(
            _AcceptedLinksInstantiator(cli=self, key="model"),
            _get_module_type(self._model_class),
            subclasses=self.subclass_mode_model,
            prepend=True,
        )

    def instantiate_trainer(self, **kwargs) -> pl.Trainer:
        """The trainer, with every logger's version fixed before any of them creates its folder.

        Recipes log to TensorBoard and CSV under the same ``save_dir/name``; each logger picks the next
        free ``version_N`` lazily, so the second would see the first's new folder and take N + 1.
        Reading all versions up front gives both the same folder.
        """
        trainer = super().instantiate_trainer(**kwargs)
        for logger in trainer.loggers:
            _ = logger.version
        return trainer


def run(argv: Sequence[str] | None = None) -> int:
    """``sm fit|validate|test|predict ARGS``: argv starts with the subcommand; returns the exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    import_task_modules()
    try:
        SkeletonMambaCLI(
            LightningModule,
            LightningDataModule,
            subclass_mode_model=True,
            subclass_mode_data=True,
            save_config_kwargs={"overwrite": True},
            parser_kwargs={
                "description": "Skeleton Mamba (LightningCLI). Pick a recipe with --recipe NAME|PATH."
            },
            args=None if args == sys.argv[1:] else args,  # LightningCLI warns when both are given
        )
    except Exception as err:
        missing = _dataset_not_found(err)
        if missing is None:
            raise
        print(f"sm {args[0] if args else ''}: {missing}", file=sys.stderr)
        return 2
    return 0


def _dataset_not_found(err: BaseException | None) -> DatasetNotFoundError | None:
    """The :class:`DatasetNotFoundError` behind ``err`` (jsonargparse wraps instantiation errors)."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, DatasetNotFoundError):
            return err
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None


def list_recipes(argv: Sequence[str] | None = None) -> int:
    """``sm recipes``: print each packaged recipe with the description from its leading ``# `` line."""
    import argparse

    parser = argparse.ArgumentParser(prog="sm recipes", description="List the packaged recipes.")
    parser.parse_args(list(argv or []))
    recipes = packaged_recipes()
    width = max((len(name) for name in recipes), default=0)
    for name, path in recipes.items():
        print(f"{name:<{width}}  {recipe_description(path)}")
    if not recipes:
        print("no packaged recipes found", file=sys.stderr)
        return 1
    return 0
