"""What every ``sm`` command's parser shares: the help formatter, the input-file check, ``--quiet``, the
sampling and precision options, each spelled alike.

argparse only: ``sm CMD --help`` builds the command's parser from a module that imports no torch (the
``*_args.py`` beside each command), and ``sm`` parses the command line with it before importing the command,
so that ``--help``, a bad argument or a missing input file answers in a fraction of a second.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable

from skeleton_mamba.errors import InputError
from skeleton_mamba.pretrained.size_bounds import SIZE_BOUNDS
from skeleton_mamba.runtime.precision import PRECISION_HELP, PRECISIONS
from skeleton_mamba.tasks.motion.io.option_types import real_option

__all__ = [
    "SAMPLERS",
    "SOLVER_NAMES",
    "CommandParser",
    "ExamplesHelpFormatter",
    "SmHelpFormatter",
    "add_precision_argument",
    "add_quiet_argument",
    "add_sampling_arguments",
    "checked_sampling",
    "command_parser",
    "progress_default",
    "sampling_overrides",
]

SAMPLERS = ("ddim", "ddpm", "dpmpp", "unipc")  # the diffusion samplers (tasks/training/diffusion/sampling.py)
MAX_SAMPLING_STEPS = SIZE_BOUNDS["sampling_steps"]
SOLVER_NAMES = ("dpmpp", "unipc")  # those of them that are multistep ODE solvers (diffusion/solvers.py)


class SmHelpFormatter(argparse.HelpFormatter):
    """argparse's help layout with a wider option column, and ``(default: X)`` where X tells something.

    The default is added after an option's help only when it is a value one would type: not for a flag
    (``--quiet``), a required option, a default of None (the help says what happens then), or a help that
    states its default already.
    """

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=32)

    def _get_help_string(self, action: argparse.Action) -> str:  # argparse's hook for the defaults
        text = action.help or ""
        if "default" in text or action.required or action.nargs == 0 or action.default is None:
            return text
        if action.default is argparse.SUPPRESS or not action.option_strings:
            return text
        return f"{text} (default: %(default)s)"


class ExamplesHelpFormatter(SmHelpFormatter):
    """:class:`SmHelpFormatter` that keeps the indented lines of an epilog of examples as they are (a command
    line is not re-wrapped); every other line is wrapped as usual."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:  # argparse's hook for the texts
        lines = []
        for line in text.splitlines():
            keep = line.startswith(" ") or line.endswith(":")  # an example, or the heading of the examples
            lines.append(indent + line if keep else super()._fill_text(line, width, indent))
        return "\n".join(lines)


class CommandParser(argparse.ArgumentParser):
    """argparse's parser that also checks the input files a command reads: an option marked with
    :meth:`input_path` whose value names nothing on disk is refused as soon as the command line is parsed,
    before the command imports torch or loads a checkpoint, as one line ``sm CMD: error: PATH: no such file
    or folder (--option)`` (an :class:`~.errors.InputError`, exit 2). ``-`` (standard input) is not
    checked."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.input_paths: list[argparse.Action] = []
        self.checks: list[Callable[[argparse.Namespace], str | None]] = []

    def input_path(self, action: argparse.Action) -> argparse.Action:
        """Mark ``action`` (what ``add_argument`` returned) as an input file or folder that must exist."""
        self.input_paths.append(action)
        return action

    def check(self, problem: Callable[[argparse.Namespace], str | None]) -> None:
        """Add a check of options against each other (``--overlap`` against ``--window``): ``problem``
        returns why the parsed options do not go together, or None; refused once the command line is parsed,
        before the input files are checked (an :class:`~.errors.InputError`, exit 2)."""
        self.checks.append(problem)

    def parse_known_args(self, args=None, namespace=None):
        namespace, extras = super().parse_known_args(args, namespace)
        for problem in self.checks:
            message = problem(namespace)
            if message is not None:
                raise InputError(message)
        for action in self.input_paths:
            value = getattr(namespace, action.dest, None)
            if value is not None and value != "-" and not os.path.exists(value):
                name = "/".join(action.option_strings) or action.dest
                raise InputError(f"{value}: no such file or folder ({name})")
        return namespace, extras


def command_parser(prog: str, description: str, epilog: str | None = None) -> CommandParser:
    """The parser of ``sm COMMAND`` (``prog``: ``"sm COMMAND"``) with :class:`SmHelpFormatter`, or
    :class:`ExamplesHelpFormatter` with an ``epilog`` of examples."""
    formatter = SmHelpFormatter if epilog is None else ExamplesHelpFormatter
    return CommandParser(prog=prog, description=description, epilog=epilog, formatter_class=formatter)


def progress_default(stream=None) -> bool:
    """Whether progress bars show by default: only when ``stream`` (default stderr) is a terminal, so that a
    log file or a pipe gets no carriage-return redraws."""
    stream = sys.stderr if stream is None else stream
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # a replaced or closed stream
        return False


_noted: set[tuple[str, str]] = set()


class _DeprecatedSpelling(argparse.Action):
    """An old spelling of an option: hidden from ``--help``, still sets ``dest`` to ``const``, and says once
    per process (``sm`` parses a command line twice: before importing the command, and in it) what to
    write instead."""

    def __init__(self, option_strings, dest, const=None, advice: str = "", **kwargs) -> None:
        super().__init__(option_strings, dest, nargs=0, const=const, help=argparse.SUPPRESS, **kwargs)
        self.advice = advice

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        if (parser.prog, option_string) not in _noted:
            _noted.add((parser.prog, option_string))
            print(f"{parser.prog}: note: {option_string} is deprecated; {self.advice}", file=sys.stderr)
        setattr(namespace, self.dest, self.const)


def add_quiet_argument(parser: argparse.ArgumentParser, what: str = "progress bars") -> None:
    """``--quiet`` (hide the ``what``) as ``args.progress``: True by default on a terminal, False in a log
    file (:func:`progress_default`) or with ``--quiet``. The old spellings ``--no-progress`` (as
    ``--quiet``) and ``--progress`` (bars show by default now) still work, hidden, with a one-line note."""
    parser.add_argument(
        "--quiet",
        action="store_false",
        dest="progress",
        default=progress_default(),
        help=f"hide the {what} (shown only when stderr is a terminal)",
    )
    parser.add_argument(
        "--no-progress", action=_DeprecatedSpelling, dest="progress", const=False, advice="use --quiet"
    )
    parser.add_argument(
        "--progress",
        action=_DeprecatedSpelling,
        dest="progress",
        const=progress_default(),
        advice=f"{what} show by default on a terminal (--quiet hides them)",
    )


def _steps(text: str) -> int:
    try:
        steps = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of sampling steps, got {text!r}") from None
    if steps < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1 sampling step, got {steps}")
    if steps > MAX_SAMPLING_STEPS:  # no model has more diffusion steps (the loaded model's: checked_sampling)
        limit = f"{MAX_SAMPLING_STEPS:,}"
        raise argparse.ArgumentTypeError(f"expected at most {limit} sampling steps, got {steps}")
    return steps


def add_sampling_arguments(parser: argparse.ArgumentParser) -> None:
    """``--sampler ddim|ddpm|dpmpp|unipc``, ``--steps N`` (alone on a DDPM model it selects DDIM),
    ``--eta`` and ``--guidance`` of the generative commands (``sm dance``, ``sm generate``), each defaulting
    to the checkpoint's :class:`~skeleton_mamba.tasks.training.diffusion.sampling.SamplingOptions`."""
    parser.add_argument("--sampler", choices=SAMPLERS, default=None, help="default: the checkpoint's")
    parser.add_argument(
        "--steps",
        type=_steps,
        default=None,
        help="steps of ddim, dpmpp or unipc (alone on a ddpm checkpoint: ddim; default: the checkpoint's, "
        "20 for a solver chosen with --sampler)",
    )
    parser.add_argument(
        "--eta",
        type=real_option(0.0, 10.0, "a DDIM eta"),
        default=None,
        help="DDIM noise eta (default: the checkpoint's)",
    )
    parser.add_argument(
        "--guidance",
        type=real_option(0.0, 100.0, "a guidance weight"),
        default=None,
        help="classifier-free guidance weight (default: the checkpoint's)",
    )


def sampling_overrides(args: argparse.Namespace) -> dict:
    """The keyword arguments of ``SamplingOptions.override`` that ``args`` gives."""
    return dict(sampler=args.sampler, sampling_steps=args.steps, eta=args.eta, guidance_weight=args.guidance)


def checked_sampling(args: argparse.Namespace, stored, num_steps: int, source: str):
    """The sampling a command runs: the checkpoint's ``stored`` ``SamplingOptions`` with the options of
    ``args`` (:func:`sampling_overrides`), checked against the loaded model's ``num_steps`` diffusion steps
    (``SamplingOptions.steps_problem``) right after the checkpoint loads, before any input is read.

    Raises:
        InputError: naming the option at fault (``--steps``, or ``--sampler`` with its default step count)
            or, when no option set the step count, the checkpoint ``source`` and its ``sampling_steps``.
    """
    sampling = stored.override(**sampling_overrides(args))
    problem = sampling.steps_problem(num_steps)
    if problem is None:
        return sampling
    if args.steps is not None:
        raise InputError(f"--steps {args.steps}: {problem}")
    if args.sampler is not None and sampling.sampling_steps != stored.sampling_steps:
        where = f"--sampler {args.sampler} (its default {sampling.sampling_steps} steps)"
    else:
        where = f"{source}: its sampling_steps {sampling.sampling_steps}"
    raise InputError(f"{where}: {problem}; choose the count with --steps")


def add_precision_argument(parser: argparse.ArgumentParser, measured: str) -> None:
    """``--precision fp32|bf16`` (:mod:`skeleton_mamba.runtime.precision`), its help ending with what was
    ``measured`` of bf16 against fp32 for this command."""
    parser.add_argument(
        "--precision", choices=PRECISIONS, default="fp32", help=f"{PRECISION_HELP} {measured}"
    )
