"""``sm``'s start: ``sm --help`` and every ``sm CMD --help`` import neither torch nor Lightning (nor any
other heavy library), a bad argument or a missing input is refused before the command's imports, and the
help texts say what they should (no column overflow, no ``(default: None)``, no RST markup, no option
without help, one ``--quiet``). Timings are ``benchmarks/bench_startup.py``'s; nothing here is timed."""

from __future__ import annotations

import argparse
import importlib
import json
import subprocess
import sys

import pytest

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.commands.cli_options import (
    CommandParser,
    SmHelpFormatter,
    add_quiet_argument,
    command_parser,
    progress_default,
)
from skeleton_mamba.tasks.training import cli
from tests.helpers.wheel_build import HEAVY as PACKAGE_HEAVY

# torch, onnxruntime and the heavy libraries of test_packaging's list (jsonargparse is light; sm's command
# table lives in the tasks' package, so importing it is no sign of a heavy import)
HEAVY = (
    "torch",
    "onnxruntime",
    *(m for m in PACKAGE_HEAVY if m not in ("jsonargparse", "skeleton_mamba.tasks")),
)
# every command line whose help comes from sm's own parsers (fit/validate/test/predict: LightningCLI's)
HELP_LINES = [["--help"]] + [
    [name, "--help"] for name in cli.available_commands() if name not in cli.LIGHTNING_SUBCOMMANDS
]
HELP_LINES.append(["stream", "--task", "recognition", "--help"])

RUNNER = """
import json, sys
from skeleton_mamba.tasks.training.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exit:
    code = exit.code
print(json.dumps({"code": code, "heavy": [m for m in HEAVY if m in sys.modules]}))
"""


def run_sm_in_fresh_process(args: list[str]) -> tuple[dict, str, str]:
    """``sm ARGS`` through ``cli.main`` in a fresh interpreter: (exit code and heavy modules loaded, stdout
    before the report, stderr)."""
    code = f"HEAVY = {HEAVY!r}\n{RUNNER}"
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120)
    *printed, report = done.stdout.rstrip("\n").split("\n")
    return json.loads(report), "\n".join(printed), done.stderr


@pytest.mark.parametrize("args", HELP_LINES, ids=" ".join)
def test_help_imports_no_heavy_library(args):
    report, out, err = run_sm_in_fresh_process(args)
    assert report == {"code": 0, "heavy": []}, err
    assert "usage: sm" in out


def test_a_missing_input_and_a_bad_argument_are_refused_before_the_command_is_imported():
    missing = ["dance", "--ckpt", "model.ckpt", "--music", "no_such_song.wav", "--out", "o"]
    report, _, err = run_sm_in_fresh_process(missing)
    assert report == {"code": 2, "heavy": []}
    assert err == "sm dance: error: no_such_song.wav: no such file or folder (--music)\n"
    report, _, err = run_sm_in_fresh_process(["generate", "--text", "a person walks", "--out", "o"])
    assert report == {"code": 2, "heavy": []}  # argparse: --checkpoint is required
    assert err.strip().endswith("sm generate: error: the following arguments are required: --checkpoint")


def test_sm_help_keeps_every_command_name_apart_from_its_help():
    out = subprocess.run(
        [sys.executable, "-m", "skeleton_mamba.tasks", "--help"], capture_output=True, text=True
    )
    lines = {
        line.split()[0]: line for line in out.stdout.splitlines() if line.startswith("  ") and line.split()
    }
    for name, command in cli.available_commands().items():
        assert lines[name].startswith(f"  {name}  ") and lines[name].endswith(command.help), lines[name]
    assert "export-pretraineda" not in out.stdout


def _parsers() -> dict[str, argparse.ArgumentParser]:
    commands = {name: c for name, c in cli.available_commands().items() if c.parser is not None}
    commands["stream --task recognition"] = cli.TASK_VARIANTS["stream"]["recognition"]
    parsers = {}
    for name, command in commands.items():
        module, function = command.parser.split(":")
        parser = getattr(importlib.import_module(module), function)()
        parsers[name] = parser
        for action in parser._actions:  # subcommands (sm prepare ntu60 ...) are parsers of their own
            if isinstance(action, argparse._SubParsersAction):
                parsers.update({f"{name} {sub}": p for sub, p in action.choices.items()})
    return parsers


PARSERS = _parsers()


@pytest.mark.parametrize("name", sorted(PARSERS))
def test_help_texts_say_what_they_should(name):
    parser = PARSERS[name]
    text = parser.format_help()
    assert "(default: None)" not in text and "(default: True)" not in text and "(default: False)" not in text
    assert "``" not in text and ":mod:" not in text and ":class:" not in text  # no RST in a terminal
    for action in parser._actions:
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._SubParsersAction):
            continue
        assert action.help, f"{name}: {action.option_strings or action.dest} has no help"
        if action.required:
            assert "(default:" not in SmHelpFormatter(parser.prog)._get_help_string(action)
    assert "--no-progress" not in text and "--progress" not in text  # one spelling: --quiet


def test_one_quiet_spelling_and_the_old_ones_still_work_once_noted(capsys, monkeypatch):
    from skeleton_mamba.tasks.motion.commands import cli_options

    monkeypatch.setattr(cli_options, "_noted", set())  # a fresh process: other tests may have been noted
    with_bars = {name for name, parser in PARSERS.items() if "--quiet" in parser.format_help()}
    expected = {"render", "evaluate-dance", "make-ego", "dance", "generate"}
    expected |= {f"prepare {dataset}" for dataset in ("ntu60", "ntu120", "kinetics")}
    assert expected <= with_bars
    required = ["--motion", "m.npz", "--out", "o"]
    make_ego = PARSERS["make-ego"]
    assert make_ego.parse_args([*required, "--quiet"]).progress is False
    assert make_ego.parse_args([*required, "--no-progress"]).progress is False
    make_ego.parse_args([*required, "--no-progress"])  # noted once per process
    assert capsys.readouterr().err == "sm make-ego: note: --no-progress is deprecated; use --quiet\n"
    dance = PARSERS["dance"].parse_args(["--ckpt", "c", "--list-samples", "--progress"])
    assert dance.progress is progress_default()
    assert (
        "sm dance: note: --progress is deprecated; progress bars show by default" in capsys.readouterr().err
    )


def test_progress_bars_show_only_on_a_terminal():
    class Stream:
        def __init__(self, tty: bool) -> None:
            self.tty = tty

        def isatty(self) -> bool:
            return self.tty

    assert progress_default(Stream(True)) is True
    assert progress_default(Stream(False)) is False
    assert progress_default(object()) is False  # a replaced stream without isatty
    parser = command_parser("sm x", "x")
    add_quiet_argument(parser)
    assert parser.parse_args([]).progress is progress_default()  # pytest captures stderr: False here
    assert parser.parse_args(["--quiet"]).progress is False


def test_the_help_formatter_shows_only_defaults_worth_reading():
    parser = command_parser("sm x", "x")
    parser.add_argument("--window", type=int, default=150, help="frames per window")
    parser.add_argument("--ckpt", required=True, help="a checkpoint")
    parser.add_argument("--name", default=None, help="file stem (default: the input's)")
    parser.add_argument("--stride", default=None, help="window stride")
    parser.add_argument("--no-render", action="store_true", help="skip the video")
    parser.add_argument("--fps", type=float, default=30.0, help="frame rate (default 30)")
    helps = {a.dest: SmHelpFormatter("sm x")._get_help_string(a) for a in parser._actions}
    assert helps["window"] == "frames per window (default: %(default)s)"
    assert helps["ckpt"] == "a checkpoint" and helps["stride"] == "window stride"
    assert helps["name"] == "file stem (default: the input's)" and helps["fps"] == "frame rate (default 30)"
    assert helps["no_render"] == "skip the video"
    assert "frames per window (default: 150)" in " ".join(parser.format_help().split())


def test_input_paths_are_checked_when_parsed(tmp_path):
    parser = CommandParser(prog="sm x")
    parser.input_path(parser.add_argument("--music"))
    parser.add_argument("--out")
    (tmp_path / "song.wav").write_bytes(b"")
    assert parser.parse_args(["--music", str(tmp_path / "song.wav")]).music == str(tmp_path / "song.wav")
    assert parser.parse_args(["--music", "-"]).music == "-"  # standard input
    assert parser.parse_args(["--out", str(tmp_path / "new")]).music is None  # outputs are not checked
    with pytest.raises(InputError, match=r"^.*none\.wav: no such file or folder \(--music\)$"):
        parser.parse_args(["--music", str(tmp_path / "none.wav")])


def test_the_protocol_names_of_the_light_parser_are_the_metrics_own():
    from skeleton_mamba.tasks.motion.commands.evaluate_dance_args import PROTOCOL_NAMES
    from skeleton_mamba.tasks.motion.metrics.protocols import PROTOCOLS

    assert PROTOCOL_NAMES == tuple(PROTOCOLS)
    assert all(PROTOCOLS[name].name == name for name in PROTOCOL_NAMES)


def test_the_sampler_and_precision_names_are_the_ones_that_run():
    from skeleton_mamba.ssd.precision import inference_precision
    from skeleton_mamba.tasks.training.diffusion.sampling import SamplingOptions

    for precision in PARSERS["dance"]._option_string_actions["--precision"].choices:
        inference_precision(precision)  # every offered precision runs
    for sampler in PARSERS["dance"]._option_string_actions["--sampler"].choices:
        SamplingOptions(sampler, 10, 1.0, 2.0)  # every offered sampler is accepted


def test_lightning_cli_builds_the_parser_of_the_subcommand_it_runs_only(capsys):
    from lightning.pytorch import LightningDataModule, LightningModule

    from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI

    class Probe(SkeletonMambaCLI):
        def _prepare_subcommand_parser(self, klass, subcommand, **kwargs):
            self.built = [*getattr(self, "built", []), subcommand]
            return super()._prepare_subcommand_parser(klass, subcommand, **kwargs)

    for only, built in (("test", ["test"]), (None, ["fit", "validate", "test", "predict"])):
        cli = Probe.__new__(Probe)
        with pytest.raises(SystemExit):
            cli.__init__(LightningModule, LightningDataModule, subclass_mode_model=True,
                         subclass_mode_data=True, only_subcommand=only, args=["test", "--help"])  # fmt: skip
        assert cli.built == built
        assert "--ckpt_path" in capsys.readouterr().out  # the test subcommand's own help
