"""``sm fit|validate|test|predict`` (LightningCLI); ``sm recipes`` lists the recipes (:mod:`.recipes_cli`).

A recipe composes a task's LightningModule and LightningDataModule through ``class_path`` /
``init_args`` (subclass mode for both), so any task runs through the same CLI::

    sm fit --recipe ntu60.yaml                          # packaged recipe (see `sm recipes`)
    sm fit --recipe my.yaml --config more.yaml --trainer.max_epochs 3 --data.init_args.root data/
    sm test --recipe ntu60.yaml --ckpt_path runs/ntu60_xsub/version_0/checkpoints/last.ckpt
    sm fit --recipe ntu60.yaml --ckpt_path last         # resume the latest run, in its own version_N
    sm fit --recipe ntu60.yaml --print_config

``--recipe`` is an alias of ``-c/--config`` (:mod:`skeleton_mamba.tasks.training.recipe_resolution`);
config files and dotted overrides merge left to right. Values that follow from the data set are
linked from the instantiated data module's contract to the model's arguments of the same names
(:meth:`SkeletonMambaCLI.link_data_contract`, derived from the two classes: nothing lists them), never typed
twice; a contract field the model takes nowhere is refused before anything is built.

Every run gets :class:`~skeleton_mamba.tasks.training.run_guards.NonFiniteLossGuard` and
:class:`~skeleton_mamba.tasks.training.run_guards.InterruptRecorder`; ``--ckpt_path`` is checked by
:mod:`skeleton_mamba.tasks.training.checkpoints` before Lightning reads it (docs/how-to/safety.md).
"""

from __future__ import annotations

import importlib
import re
import sys
from collections.abc import Sequence
from pathlib import Path

import lightning.pytorch as pl
from lightning.pytorch import LightningDataModule, LightningModule
from lightning.pytorch.cli import ArgsType, LightningArgumentParser, LightningCLI

from skeleton_mamba import __version__
from skeleton_mamba.config import ConfigValueError
from skeleton_mamba.errors import CheckpointError, InputError, expected_failure
from skeleton_mamba.tasks.training.base_data import LINK_PREFIX
from skeleton_mamba.tasks.training.checkpoints import (
    check_state_fits,
    checked_state_shapes,
    load_checkpoint,
    use_checked_checkpoint_io,
)
from skeleton_mamba.tasks.training.contract_links import contract_class_of, contract_links
from skeleton_mamba.tasks.training.lightning_compat import import_policy, install_accepted_links
from skeleton_mamba.tasks.training.model_summary import with_parameter_summary
from skeleton_mamba.tasks.training.prediction_rig import (
    PredictionRig,
    add_prediction_rig_arguments,
    prediction_rig_from,
)
from skeleton_mamba.tasks.training.pretrained import checkpoint_file_from, is_checkpoint_source
from skeleton_mamba.tasks.training.progress_bar import with_default_progress_bar
from skeleton_mamba.tasks.training.recipe_policy import (
    ALLOW_IMPORT_ENV,
    ALLOW_IMPORT_OPTION,
    check_allowed_modules,
    check_config_values,
    refused_import_message,
    split_allow_import,
)
from skeleton_mamba.tasks.training.recipe_resolution import (
    RecipeConfigAction,
    install_bounded_yaml_loader,
)
from skeleton_mamba.tasks.training.registry import describe_error, registered_tasks
from skeleton_mamba.tasks.training.run_folders import (
    find_last_checkpoint,
    open_csv_logs,
    remove_if_empty,
    resume_in_run_folder,
)
from skeleton_mamba.tasks.training.run_guards import (
    InterruptRecorder,
    NonFiniteLossGuard,
    check_trained,
    silence_interrupt_notice,
)

__all__ = ["SkeletonMambaCLI", "import_task_modules", "quiet_as_trainer_option", "run"]


def registered_links() -> list[tuple[str, str]]:
    """The data-to-model links of every registered task: for each data-module class with a contract and each
    LightningModule class of its task's modules (:attr:`.registry.TaskSpec.modules`), the links derived from
    the two (:func:`~.contract_links.contract_links`; a pair that does not fit adds none), each once."""
    links: dict[tuple[str, str], None] = {}
    for spec in registered_tasks():
        classes = [
            value
            for name in spec.modules
            for value in vars(importlib.import_module(name)).values()
            if isinstance(value, type) and value.__module__ == name
        ]
        models = [c for c in classes if issubclass(c, LightningModule)]
        for data in filter(None, map(contract_class_of, classes)):
            for model in models:
                try:
                    links.update(dict.fromkeys(contract_links(data, model)))
                except InputError:
                    continue
    return list(links)


def import_task_modules() -> list[str]:
    """Import every registered task's module and data-module modules (:attr:`.registry.TaskSpec.modules`),
    so that recipes may use short class names (``class_path: ActionRecognitionModule``); returns their
    names. A plugin's module that fails to import (anything but Ctrl-C, a ``SystemExit`` included) is
    skipped with one warning line naming the task and the module: the built-in recipes keep working."""
    imported = []
    for spec in registered_tasks():
        builtin = spec.package == "skeleton_mamba" or spec.package.startswith("skeleton_mamba.")
        for name in spec.modules:
            try:
                importlib.import_module(name)
            except KeyboardInterrupt:
                raise
            except BaseException as err:
                if builtin:
                    raise
                print(
                    f"sm: warning: task plugin {spec.name!r}: its module {name} does not import "
                    f"({describe_error(err)}); recipes cannot name its classes",
                    file=sys.stderr,
                )
                continue
            imported.append(name)
    return imported


MAX_MESSAGE_CHARS = 400  # a parse error as ``sm`` prints it (a quoted value is cut first)
_DENIED_IMPORT = re.compile(r"Importing '([\w.]+)' is not allowed")


def one_line_parse_message(message: str) -> str:
    """jsonargparse's error as one short line: no usage, no Union bookkeeping, a long value cut.

    A refused class path (:mod:`.recipe_policy`) becomes the policy's own message, keeping the recipe file
    the message starts with.
    """
    text = " ".join(line.strip() for line in message.splitlines() if line.strip())
    text = text.replace('Parser key "config": ', "")
    denied = _DENIED_IMPORT.search(text)
    if denied is not None:
        source = re.match(r"^(\S+\.(?:ya?ml|ckpt)(?: \(hyper-parameters\))?): ", text)
        return (f"{source.group(1)}: " if source else "") + refused_import_message(denied.group(1))
    text = re.sub(
        r"Does not validate against any of the Union subtypes Subtypes: \[.*?\] Errors: - ", "", text
    )
    text = re.sub(r" - Expected a <class 'NoneType'>(\. Got value: \S+)?", "", text)
    text = re.sub(r" Given value type: <class '[\w.]+'>", "", text)
    text = re.sub(r"Expected a <class '([\w.]+)'>", r"expected \1", text)
    text = re.sub(r"<class '([\w.]+)'>", r"\1", text)
    text = re.sub(r"(Given value: .{60}).+$", r"\1...", text)
    return text if len(text) <= MAX_MESSAGE_CHARS else text[: MAX_MESSAGE_CHARS - 3] + "..."


class OneLineErrorParser(LightningArgumentParser):
    """A parse error is an :class:`~skeleton_mamba.errors.InputError` on one line, which ``sm``
    prints with exit status 2 like every command's errors (jsonargparse prints the whole usage first).

    ``error_source`` (set once the command line is parsed: the checkpoint whose hyper-parameters Lightning
    parses next) starts the message when the message names no file of its own.
    """

    error_source: str | None = None

    def error(self, message: str, ex: Exception | None = None):
        if not self.exit_on_error:  # jsonargparse trying alternatives: it catches the ArgumentError
            super().error(message, ex)
        text = one_line_parse_message(message)
        if self.error_source and not text.startswith(self.error_source):
            text = f"{self.error_source}: {text}"
        raise InputError(text) from ex


class SkeletonMambaCLI(LightningCLI):
    """LightningCLI with ``--recipe``, the data-to-model links of :meth:`link_data_contract` and one-line
    parse errors (``parser_class`` defaults to :class:`OneLineErrorParser`)."""

    def __init__(
        self,
        *args,
        parser_class: type[LightningArgumentParser] = OneLineErrorParser,
        only_subcommand: str | None = None,
        **kwargs,
    ):
        self.only_subcommand = only_subcommand
        self._link_parsers: list[LightningArgumentParser] = []
        super().__init__(*args, parser_class=parser_class, **kwargs)

    def subcommands(self) -> dict[str, set[str]]:
        """Lightning's subcommands, or only ``only_subcommand``: ``sm`` runs one per process, so the parsers
        of the other three (the trainer's, model's and data's options each) are not built (start-up time:
        ``benchmarks/README.md``)."""
        every = LightningCLI.subcommands()
        return every if self.only_subcommand is None else {self.only_subcommand: every[self.only_subcommand]}

    def init_parser(self, **kwargs) -> LightningArgumentParser:
        """The base parser, with one config action answering to ``-c``, ``--config`` and ``--recipe``.

        jsonargparse's YAML loader is bounded first (:func:`~.recipe_resolution.check_yaml_bounds`).
        """
        install_bounded_yaml_loader()
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
        """The registered tasks' data-to-model links (:func:`registered_links`), each reading the data
        module's contract (``data.contract__<field>``, :class:`~.base_data.ContractDataModule`): linked
        arguments are not options (jsonargparse sets them). A link whose field the chosen data module's
        contract does not have is skipped; :meth:`link_data_contract` checks the chosen pair once parsed."""
        for field, target in registered_links():
            parser.link_arguments(
                f"data.{LINK_PREFIX}{field}", f"model.init_args.{target}", apply_on="instantiate"
            )
        self._link_parsers.append(parser)
        if self.only_subcommand == "predict":  # sm predict --rig RIG [--map]: the dances on a character too
            add_prediction_rig_arguments(parser)

    def link_data_contract(self) -> list[tuple[str, str]]:
        """The links of the chosen data module's contract and the chosen model
        (:func:`~.contract_links.contract_links`: a field the model takes nowhere is refused here, before
        anything is built); those no registered pair has (a data module or model outside the registered tasks'
        modules) are added to the running subcommand's parser. Returns the links (none when the data module
        declares no contract).

        LightningCLI builds one parser per subcommand (``sm`` one only) and calls
        :meth:`add_arguments_to_parser` with each, in :meth:`subcommands` order, so the running subcommand's
        parser is found by its place.
        """
        config = _subcommand_config(self.config, self.subcommand)
        data_class = _class_of(config.get("data"))
        model_class = _class_of(config.get("model"))
        contract_class = None if data_class is None else contract_class_of(data_class)
        if contract_class is None or model_class is None:
            return []
        links = contract_links(contract_class, model_class)
        names = list(self.subcommands())
        parser = self._link_parsers[names.index(self.subcommand) if self.subcommand in names else -1]
        known = set(registered_links())
        for field, target in links:
            if (field, target) not in known:
                parser.link_arguments(
                    f"data.{LINK_PREFIX}{field}", f"model.init_args.{target}", apply_on="instantiate"
                )
        return links

    def parse_arguments(self, parser: LightningArgumentParser, args: ArgsType) -> None:
        """Parse, then check ``--ckpt_path`` before Lightning reads it (:mod:`.checkpoints`).

        ``last`` becomes the last checkpoint of the latest run of this recipe; the file must be local and
        load with ``weights_only=True``, and the class paths in its hyper-parameters must be the project's,
        all before Lightning parses them (which imports the classes they name). ``sm fit`` resumes in the
        checkpoint's own run folder (:func:`~.run_folders.resume_in_run_folder`). The trainer method's
        ``weights_only`` is set to True, so that Lightning's own load of the checkpoint is restricted too.
        ``sm predict --rig`` reads and maps its rig first (:mod:`.prediction_rig`).
        """
        super().parse_arguments(parser, args)
        subcommand = self.config.get("subcommand")
        config = self.config.get(subcommand) if subcommand else None
        if config is None:
            return
        sources = [str(p) for p in (config.get("config") or []) if p is not None]
        check_config_values(config.as_dict(), sources)
        if subcommand == "predict":  # --rig read and mapped before the checkpoint, the model and the data
            self.prediction_rig = prediction_rig_from(config)
        if "weights_only" in config:  # the Trainer method's argument (Lightning >= 2.6)
            config.weights_only = True
        ckpt_path = config.get("ckpt_path")
        if ckpt_path is not None:
            if str(ckpt_path) == "last":
                ckpt_path = str(find_last_checkpoint(config.trainer))
                config.ckpt_path = ckpt_path
            source = str(ckpt_path)  # what messages name: the folder, not the checkpoint written from it
            if subcommand != "fit" and not is_checkpoint_source(ckpt_path):  # an exported folder, a Hub id
                ckpt_path = config.ckpt_path = str(checkpoint_file_from(ckpt_path))
            try:
                shapes = checked_state_shapes(load_checkpoint(ckpt_path), ckpt_path)
            except CheckpointError as err:
                raise CheckpointError(str(err).replace(str(ckpt_path), source)) from err
            self.checkpoint_shapes = (source, shapes)
            if isinstance(parser, OneLineErrorParser):  # Lightning parses its hyper-parameters next
                parser.error_source = f"{source} (hyper-parameters)"
            if subcommand == "fit":
                resume_in_run_folder(config.trainer, Path(ckpt_path))

    checkpoint_shapes: tuple[str, dict] | None = None  # --ckpt_path and its tensors' shapes
    prediction_rig: PredictionRig | None = None  # sm predict --rig (:mod:`.prediction_rig`)

    def _check_checkpoint_fits(self) -> None:
        """``--ckpt_path``'s tensors against the instantiated model, before the trainer loads them."""
        if self.checkpoint_shapes is not None:
            check_state_fits(self.model, self.checkpoint_shapes[1], self.checkpoint_shapes[0])

    before_fit = before_validate = before_test = before_predict = _check_checkpoint_fits

    def before_instantiate_classes(self) -> None:
        """Lightning's model instantiator, given only the linked values the model accepts.

        Lightning stores every applied data-to-model link in the checkpoint's hyper-parameters and parses
        them back on ``--ckpt_path``; a link the model has no argument for (``batch_size`` on a module
        without one) would then break ``sm test|predict --ckpt_path``
        (:mod:`skeleton_mamba.tasks.training.lightning_compat`).
        """
        install_accepted_links(self)
        self.link_data_contract()

    def instantiate_classes(self) -> None:
        """Lightning's instantiation, a class refusing its settings as one line.

        jsonargparse wraps the refusal of a nested config (``MixerConfig(chunk_size=0)``,
        ``DanceSampling(sampler="evil")``) in a dump of the whole model namespace; the refusal it wraps (the
        first error of its chain) is what the message says, naming the option where the refused value
        is found in the parsed config (:func:`refused_setting_message`).
        """
        try:
            super().instantiate_classes()
        except ValueError as err:
            if expected_failure(err) is not None:  # the project's own error (missing data): sm prints it
                raise
            config = _subcommand_config(self.config, self.subcommand)
            sources = [str(p) for p in (config.get("config") or []) if p is not None]
            raise InputError(refused_setting_message(err, config.as_dict(), sources)) from err

    def instantiate_trainer(self, **kwargs) -> pl.Trainer:
        """The trainer, with every logger's version fixed before any of them creates its folder.

        Recipes log to TensorBoard and CSV under the same ``save_dir/name``; each logger picks the next
        free ``version_N`` lazily, so the second would see the first's new folder and take N + 1.
        Reading all versions up front gives both the same folder. The folders this run creates are
        recorded so that a run stopping before it wrote anything leaves none behind. The progress bar shows
        the epoch total (:mod:`.progress_bar`: plain lines where no terminal shows it) and the model summary
        has no FLOPs column of zeros (:mod:`.model_summary`), unless the recipe configures its own.
        """
        config = {**_subcommand_config(self.config_init, self.subcommand).get("trainer", {}), **kwargs}
        callbacks = with_default_progress_bar(config.get("callbacks"), config.get("enable_progress_bar"))
        summary = with_parameter_summary(callbacks, config.get("enable_model_summary"))
        kwargs["callbacks"], kwargs["enable_model_summary"] = summary
        if self.prediction_rig is not None:
            kwargs["callbacks"] = [*(kwargs["callbacks"] or []), self.prediction_rig]
        trainer = super().instantiate_trainer(**kwargs)
        use_checked_checkpoint_io(trainer)  # checked reads, writes through a temporary file beside the target
        for logger in trainer.loggers:
            _ = logger.version
        recorder = next((c for c in trainer.callbacks if isinstance(c, InterruptRecorder)), None)
        if recorder is not None:  # each new run folder, then its new parents (runs/<name>/, runs/)
            new = [Path(logger.log_dir) for logger in trainer.loggers if logger.log_dir]
            new = [p for folder in new for p in (folder, *folder.parents) if not p.exists()]
            recorder.new_run_dirs = sorted(set(new), key=lambda p: -len(p.parts))
        open_csv_logs(trainer.loggers)
        return trainer


def _first_error(err: BaseException) -> BaseException:
    """The error a chain of wrappers started from (``__cause__``, else ``__context__``, to its end)."""
    seen = {id(err)}
    while True:
        inner = err.__cause__ or err.__context__
        if inner is None or id(inner) in seen:
            return err
        seen.add(id(inner))
        err = inner


def _options_holding(config: dict, name: str, value) -> list[str]:
    """The dotted options of ``config`` whose last key is ``name`` and whose value is ``value``."""
    found, stack = [], [("", config)]
    while stack:
        where, node = stack.pop()
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
        for key, item in items:
            path = f"{where}.{key}" if isinstance(key, str) else f"{where}[{key}]"
            path = path.lstrip(".")
            if key == name and (item == value or (isinstance(item, list) and tuple(item) == value)):
                found.append(path)
            elif isinstance(item, (dict, list)):
                stack.append((path, item))
    return found


def refused_setting_message(err: BaseException, config: dict, sources: list[str]) -> str:
    """One line for a class refusing its settings while a recipe is instantiated: the first error of
    ``err``'s chain; a :class:`~skeleton_mamba.config.ConfigValueError` names the one option of the parsed
    ``config`` holding the refused value (``--model.init_args.backbone.mixer.chunk_size = 0: ...``)."""
    first = _first_error(err)
    origin = f" (from {', '.join(sources)} or the command line)" if sources else ""
    if isinstance(first, ConfigValueError):
        options = _options_holding(config, first.field, first.value)
        if len(options) == 1:
            return f"--{options[0]} = {first.value!r}: {first.rule}{origin}"
    lines = str(first).strip().splitlines()
    text = lines[0] if lines else type(first).__name__
    return one_line_parse_message(f"{text}{origin}")


def _class_of(component) -> type | None:
    """The class a parsed ``model`` / ``data`` entry names by its ``class_path`` (the parse imported it);
    None for an entry without one."""
    path = component.get("class_path") if hasattr(component, "get") else None
    if not isinstance(path, str) or "." not in path:
        return None
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name, None)


def _subcommand_config(config, subcommand: str | None):
    """The part of a parsed (or instantiated) config for ``subcommand``; all of it without one."""
    return config.get(str(subcommand), config) if subcommand is not None else config


QUIET_OPTION = "--quiet"  # every sm command's spelling: here --trainer.enable_progress_bar false


def quiet_as_trainer_option(args: list[str]) -> list[str]:
    """``args`` with ``--quiet`` (after the subcommand) as ``--trainer.enable_progress_bar false``."""
    if QUIET_OPTION not in args:
        return args
    return [a for a in args if a != QUIET_OPTION] + ["--trainer.enable_progress_bar", "false"]


def run(argv: Sequence[str] | None = None) -> int:
    """``sm fit|validate|test|predict ARGS``: argv starts with the subcommand; returns the exit code."""
    given = list(sys.argv[1:] if argv is None else argv)
    args, allowed_modules = split_allow_import(given)
    args = quiet_as_trainer_option(args)
    from_command_line = given == sys.argv[1:]
    if from_command_line:  # LightningCLI reads sys.argv itself (and warns when args repeat it)
        sys.argv[1:] = args
    with import_policy(check_allowed_modules(allowed_modules)):
        return _run(args, None if from_command_line else args)


def _run(args: list[str], cli_args: list[str] | None) -> int:
    import_task_modules()
    recorder = InterruptRecorder()
    silence_interrupt_notice()
    try:
        cli = SkeletonMambaCLI(
            LightningModule,
            LightningDataModule,
            only_subcommand=args[0] if args and args[0] in LightningCLI.subcommands() else None,
            subclass_mode_model=True,
            subclass_mode_data=True,
            save_config_kwargs={"overwrite": True},
            trainer_defaults={"callbacks": [NonFiniteLossGuard(), recorder]},
            parser_kwargs={
                "description": "Skeleton Mamba (LightningCLI). Pick a recipe with --recipe NAME|PATH "
                f"(sm recipes lists them); {QUIET_OPTION} hides the progress bar. "
                f"Class paths outside the project's modules are refused unless trusted with "
                f"{ALLOW_IMPORT_OPTION} MODULE (repeatable, before or after the subcommand's options) or "
                f"{ALLOW_IMPORT_ENV}=mod1,mod2."
            },
            args=cli_args,
        )
        if cli.subcommand == "fit":
            check_trained(cli.trainer)
    except SystemExit as err:
        _remove_empty_run_dirs(recorder)
        if recorder.stopped_by == "interrupt":  # Lightning turns Ctrl-C into sys.exit(1)
            raise KeyboardInterrupt from None
        if recorder.stopped_by == "sigterm":  # Lightning's SIGTERMException exits with code 0
            saved = f"; saved {recorder.saved}" if recorder.saved else ""
            print(f"sm {args[0]}: stopped by SIGTERM{saved}", file=sys.stderr)
            return EXIT_SIGTERM
        raise err
    except BaseException:
        _remove_empty_run_dirs(recorder)
        raise
    return 0


EXIT_SIGTERM = 143  # 128 + SIGTERM, as shells report a process ended by it


def _remove_empty_run_dirs(recorder: InterruptRecorder) -> None:
    for folder in recorder.new_run_dirs:
        remove_if_empty(folder)
