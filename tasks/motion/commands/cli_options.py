"""What every ``sm`` command's parser shares: the help formatter, the input-file check, ``--quiet``, the
precision option, each spelled alike (the generative commands' sampling options:
:mod:`skeleton_mamba.tasks.training.sampling_args`).

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
from skeleton_mamba.runtime.precision import PRECISION_HELP, PRECISIONS

__all__ = [
    "CommandParser",
    "ExamplesHelpFormatter",
    "SmHelpFormatter",
    "add_precision_argument",
    "add_quiet_argument",
    "command_parser",
    "progress_default",
]


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


def add_precision_argument(parser: argparse.ArgumentParser, measured: str) -> None:
    """``--precision fp32|bf16`` (:mod:`skeleton_mamba.runtime.precision`), its help ending with what was
    ``measured`` of bf16 against fp32 for this command."""
    parser.add_argument(
        "--precision", choices=PRECISIONS, default="fp32", help=f"{PRECISION_HELP} {measured}"
    )
