"""Hostile JSON and YAML files (issue 43): one bounded reader for all of them.

:mod:`skeleton_mamba.io.bounded_read` reads regular files only (a FIFO, a link to an endless device, a link
loop are refused without blocking or growing), at most a stated size, JSON nested at most a stated depth and
holding finite numbers. Each of the project's readers is checked to go through it: a pretrained folder's
``config.json``, the viewer's ``--metrics``, a sample's ``meta.json``, a recipe and a backbone file.
"""

from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import time

import pytest

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.bounded_read import BoundedReadError, parse_json, read_bytes, read_json, read_text
from skeleton_mamba.pretrained.mixin import PretrainedError, read_pretrained_config
from skeleton_mamba.tasks.egodance.builder.layout import sample_problem
from skeleton_mamba.tasks.training.recipe_resolution import read_yaml_file
from tests.helpers.sm import sm_executable

MEMORY_LIMIT = 2 << 30  # address space of the `sm` subprocesses: an endless read would pass it


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


@pytest.fixture
def special_files(tmp_path):
    """A FIFO, a link to /dev/zero, a link loop and a folder, as a reader would be handed them."""
    os.mkfifo(tmp_path / "fifo.json")
    (tmp_path / "zero.json").symlink_to("/dev/zero")
    (tmp_path / "loop.json").symlink_to(tmp_path / "loop.json")
    (tmp_path / "folder.json").mkdir()
    return tmp_path


@pytest.mark.parametrize(
    "name, expected",
    [
        ("fifo.json", "a FIFO (named pipe), not a regular file"),
        ("zero.json", "a character device, not a regular file"),
        ("folder.json", "a folder, not a regular file"),
    ],
)
def test_special_files_are_refused_at_once(special_files, name, expected):
    start = time.monotonic()
    with pytest.raises(BoundedReadError, match=re.escape(expected)) as info:
        read_json(special_files / name)
    assert str(special_files / name) in str(info.value) and time.monotonic() - start < 5


def test_a_link_loop_is_the_os_error_naming_the_file(special_files):
    with pytest.raises(OSError, match="Too many levels of symbolic links") as info:
        read_json(special_files / "loop.json")
    assert info.value.filename == str(special_files / "loop.json")


def test_size_is_bounded_before_reading(tmp_path):
    path = tmp_path / "big.json"
    path.write_text("[" + "1," * 50 + "1]")
    assert read_json(path, max_bytes=200) == [1] * 51
    with pytest.raises(BoundedReadError, match=r"big.json: 103 bytes, more than a JSON file's 100"):
        read_json(path, max_bytes=100)
    assert read_bytes(path, max_bytes=103) == path.read_bytes()


def test_nesting_is_bounded_with_line_and_column():
    text = '{"a":\n [[1, "[[[[[[[[[[[["]]}'  # brackets inside strings do not count: depth 3
    assert parse_json(text, "t", max_depth=3) == {"a": [[1, "[" * 12]]}
    with pytest.raises(BoundedReadError, match=r"^t:2:3: nested more than 2 levels deep$"):
        parse_json(text, "t", max_depth=2)
    with pytest.raises(BoundedReadError, match="nested more than 64 levels deep"):
        parse_json("[" * 100_000 + "]" * 100_000, "t")  # no RecursionError


@pytest.mark.parametrize(
    "text, where, token",
    [
        ('{"x": NaN}', "1:7", "NaN"),
        ('{"x": "NaN",\n "y": [1, -Infinity]}', "2:11", "-Infinity"),
        ("[1.5, 1e400]", "1:7", "1e400"),
    ],
)
def test_non_finite_numbers_are_refused_where_they_are(text, where, token):
    with pytest.raises(BoundedReadError, match=rf"^t:{where}: {token} is not a finite number"):
        parse_json(text, "t")
    assert "null" in json.dumps(parse_json(text, "t", non_finite="null"), allow_nan=False)


def test_integers_and_encoding_are_bounded(tmp_path):
    with pytest.raises(BoundedReadError, match="an integer of 19 digits"):
        parse_json("[" + "9" * 19 + "]", "t")
    assert parse_json("[" + "9" * 18 + "]", "t") == [10**18 - 1]
    path = tmp_path / "latin1.json"
    path.write_bytes(b'{"x": "\xe9"}')
    with pytest.raises(BoundedReadError, match="latin1.json: not UTF-8 text"):
        read_json(path)
    with pytest.raises(BoundedReadError, match="latin1.json: not UTF-8 text"):
        read_text(path, max_bytes=100)


def test_the_error_type_is_the_callers(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text("{")
    with pytest.raises(InputError, match=r"bad.json:1:2: not valid JSON"):
        read_json(path, error=InputError)


# ------------------------------------------------------------------------------ the project's readers


def test_pretrained_config_json_goes_through_the_reader(special_files, tmp_path):
    folder = tmp_path / "net"
    folder.mkdir()
    os.mkfifo(folder / "config.json")
    with pytest.raises(PretrainedError, match="config.json: a FIFO"):
        read_pretrained_config(folder)
    (folder / "config.json").unlink()
    (folder / "config.json").write_text(
        '{"format": "skeleton-mamba-pretrained", "x": ' + "[" * 100 + "]" * 100 + "}"
    )
    with pytest.raises(PretrainedError, match="config.json:1:.*nested more than 64 levels deep"):
        read_pretrained_config(folder)
    (folder / "config.json").write_text(" " * (2 << 20))
    with pytest.raises(PretrainedError, match=r"config.json: 2,097,152 bytes, more than a config.json's"):
        read_pretrained_config(folder)


def test_sample_meta_json_goes_through_the_reader(tmp_path):
    (tmp_path / "meta.json").symlink_to("/dev/zero")
    problem = sample_problem(tmp_path)
    assert problem is not None and "a character device" in problem


def test_yaml_files_go_through_the_reader(tmp_path):
    os.mkfifo(tmp_path / "backbone.yaml")
    with pytest.raises(InputError, match="backbone.yaml: a FIFO"):
        read_yaml_file(tmp_path / "backbone.yaml", "backbone file")
    (tmp_path / "broken.yaml").write_text("a: [1,\nb: 2\n")
    with pytest.raises(InputError, match=r"broken.yaml:3:1: YAML syntax error in the recipe"):
        read_yaml_file(tmp_path / "broken.yaml")


@pytest.mark.parametrize("option", ["--metrics", "--recipe"])
def test_sm_refuses_a_fifo_or_an_endless_link_on_one_line(tmp_path, option):
    """``sm view --metrics FIFO`` and ``sm fit --recipe LINK-TO-/dev/zero``: one line, at once, no memory."""
    from skeleton_mamba.tasks.motion.formats.motion_file import save_motion
    from tests.helpers.motions import _smpl_motion

    if option == "--metrics":
        os.mkfifo(tmp_path / "metrics.json")
        save_motion(tmp_path / "m.npz", _smpl_motion(4))
        args = ["view", str(tmp_path / "m.npz"), "--metrics", str(tmp_path / "metrics.json")]
        args += ["--out", str(tmp_path / "v.html")]
        bad, expected = tmp_path / "metrics.json", "a FIFO (named pipe), not a regular file"
    else:
        (tmp_path / "recipe.yaml").symlink_to("/dev/zero")
        args = ["fit", "--recipe", str(tmp_path / "recipe.yaml")]
        bad, expected = tmp_path / "recipe.yaml", "a character device, not a regular file"
    start = time.monotonic()
    proc = subprocess.run(
        [sm_executable(), *args], capture_output=True, text=True, timeout=120, preexec_fn=_limit_memory,
        cwd=tmp_path,
    )  # fmt: skip
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr[-2000:]
    assert str(bad) in lines[0] and expected in lines[0], lines
    assert time.monotonic() - start < 60 and not (tmp_path / "v.html").exists()
