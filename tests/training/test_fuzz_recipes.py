"""Hostile and careless recipes and options (issue 33): refused on one line, exit 2, nothing run or written.

Classes generated here: out-of-range numbers (``1e1000`` epochs, a 24-digit seed, negative or zero counts, a
ten-billion-day ``max_time``, a 1e14-frame clip, an infinite fraction), class paths of a module outside the
project (a module written into ``tmp_path``, put on ``sys.path``, that creates a marker file when imported:
it must not exist after a refusal, and must after ``--allow-import`` / ``SM_ALLOW_IMPORT``), jsonargparse's
deny-list (``os.system``), files that are not recipes (``base: /etc/passwd``), refusals of a checkpoint's
hyper-parameters, and training-data errors (labels outside the classes, joint-count mismatch, a missing,
empty or dangling split). The expected ranges are written out by hand from Lightning's documentation
(``max_epochs`` -1 or >= 0, seeds 0 to 2**32 - 1, ``limit_*_batches`` an int or a fraction in [0, 1]).
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import jsonargparse
import pytest
import torch
from lightning.pytorch import Callback, LightningDataModule, LightningModule

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.recognition.synthetic import make_synthetic_annotations
from skeleton_mamba.tasks.training.cli import main as sm_main
from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI, import_task_modules
from skeleton_mamba.tasks.training.lightning_compat import import_policy
from skeleton_mamba.tasks.training.recipe_policy import (
    TRUSTED_MODULES,
    check_allowed_modules,
    check_config_values,
    split_allow_import,
)
from skeleton_mamba.tasks.training.recipe_resolution import packaged_recipes
from tests.helpers.sm import sm_executable

SYNTHETIC = "recognition_synthetic.yaml"


def _refused(args: list[str], capsys, work: Path, expected: str) -> str:
    """Run ``sm ARGS`` in ``work``: exit 2, one line naming ``expected``, no traceback, nothing written."""
    assert sm_main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    assert expected in err[0], err[0]
    assert list(work.iterdir()) == [], list(work.iterdir())
    return err[0]


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "work"
    folder.mkdir()
    monkeypatch.chdir(folder)
    monkeypatch.delenv("SM_ALLOW_IMPORT", raising=False)
    return folder


# --- numbers ------------------------------------------------------------------------------------

OUT_OF_RANGE = [
    (["--trainer.max_epochs", "1e1000"], '"trainer.max_epochs": expected int'),
    (
        ["--trainer.max_epochs", "-7"],
        "--trainer.max_epochs = -7: expected an integer, -1, or 0 to 2,147,483,647",
    ),
    (["--trainer.max_epochs", str(2**31)], "--trainer.max_epochs = 2147483648"),
    (["--trainer.max_steps", "-5"], "--trainer.max_steps = -5"),
    (["--trainer.max_steps", "9" * 24], "--trainer.max_steps = 999999999999999999999999"),
    (["--seed_everything", "1" * 24], "--seed_everything = 111111111111111111111111: expected true, false"),
    (["--seed_everything", "-5"], "--seed_everything = -5"),
    (["--seed_everything", str(2**32)], "--seed_everything = 4294967296"),
    (["--trainer.max_time", "99999999999:00:00:00"], "--trainer.max_time = '99999999999:00:00:00': is more"),
    (["--trainer.max_time", "{days: -1}"], "--trainer.max_time = {'days': -1}: is not a mapping"),
    (["--trainer.limit_train_batches", "1e400"], "--trainer.limit_train_batches = inf"),
    (["--trainer.limit_val_batches", "1.5"], "--trainer.limit_val_batches = 1.5"),
    (["--trainer.val_check_interval", "0.0"], "--trainer.val_check_interval = 0.0"),
    (["--trainer.accumulate_grad_batches", "0"], "--trainer.accumulate_grad_batches = 0"),
    (
        ["--data.init_args.batch_size", "0"],
        "--data.init_args.batch_size = 0: expected an integer, 1 to 65,536",
    ),
    (["--data.init_args.batch_size", "9" * 20], "--data.init_args.batch_size = 99999999999999999999"),
    (["--data.init_args.num_workers", "100000"], "--data.init_args.num_workers = 100000"),
    (["--data.init_args.num_frames", "100000000000000"], "--data.init_args.num_frames = 100000000000000"),
    (["--data.init_args.train_per_class", "-1"], "--data.init_args.train_per_class = -1"),
    (["--model.init_args.lr", "-0.5"], "--model.init_args.lr = -0.5"),
    (["--model.init_args.base_batch_size", "0"], "--model.init_args.base_batch_size = 0"),
]


@pytest.mark.parametrize(("option", "expected"), OUT_OF_RANGE, ids=[" ".join(o) for o, _ in OUT_OF_RANGE])
def test_out_of_range_numbers_are_one_line_errors(option, expected, work, capsys):
    line = _refused(["fit", "--recipe", SYNTHETIC, *option], capsys, work, expected)
    if "=" in expected.split(":")[0]:  # ours: names where the value may come from
        assert "recognition_synthetic.yaml or the command line" in line


def test_durations_and_fps_of_other_tasks_are_bounded(work, capsys):
    _refused(
        ["fit", "--recipe", "stream_dance_demo.yaml", "--data.init_args.synthetic_duration_s", "1e9"],
        capsys,
        work,
        "--data.init_args.synthetic_duration_s = 1000000000.0: expected a number from 0 to 86400",
    )


def _accepts(config: dict) -> bool:
    try:
        check_config_values(config)
    except InputError:
        return False
    return True


def test_the_range_boundaries_are_lightnings():
    # Hand-written from the Trainer / seed_everything documentation, both sides of each boundary.
    for value, ok in [(-1, True), (0, True), (2**31 - 1, True), (-2, False), (2**31, False)]:
        assert _accepts({"trainer": {"max_epochs": value}}) is ok, value
        assert _accepts({"trainer": {"max_steps": value}}) is ok, value
    for value, ok in [(0, True), (2**32 - 1, True), (True, True), (False, True), (-1, False), (2**32, False)]:
        assert _accepts({"seed_everything": value}) is ok, value
    for value, ok in [(0, True), (0.0, True), (1.0, True), (10, True), (1.0001, False), (-1, False)]:
        assert _accepts({"trainer": {"limit_train_batches": value}}) is ok, value
    for value, ok in [(1, True), (0.25, True), (1.0, True), (0.0, False), (0, False)]:
        assert _accepts({"trainer": {"val_check_interval": value}}) is ok, value
    for value, ok in [
        ("00:12:00:00", True),
        ("3650:00:00:00", True),
        ("3651:00:00:00", False),
        ("1:2", False),
    ]:
        assert _accepts({"trainer": {"max_time": value}}) is ok, value
    # infinite floats without a rule stay allowed (a mixer's dt_limit = (0, inf)); huge integers do not
    assert _accepts({"model": {"init_args": {"network": {"dt_limit": [0.0, float("inf")]}}}})
    assert not _accepts({"model": {"init_args": {"width": 2**63}}})
    assert _accepts({"model": {"init_args": {"width": 2**63 - 1}}})


class _Parsed(Exception):
    pass


class _ParseOnlyCLI(SkeletonMambaCLI):
    """Parses (our checks included), then stops before anything is instantiated."""

    def before_instantiate_classes(self) -> None:
        raise _Parsed


@pytest.mark.parametrize("name", sorted(packaged_recipes()))
def test_packaged_recipes_pass_the_value_checks_and_the_import_policy(name, work):
    import_task_modules()
    with import_policy(check_allowed_modules(())), pytest.raises(_Parsed):
        _ParseOnlyCLI(
            LightningModule,
            LightningDataModule,
            subclass_mode_model=True,
            subclass_mode_data=True,
            args=["fit", "--recipe", name],
        )


# --- class paths --------------------------------------------------------------------------------


def _foreign_module(tmp_path: Path, monkeypatch, name: str) -> Path:
    """A module ``name`` on ``sys.path`` that, when imported, creates a marker file; it holds a Callback."""
    folder = tmp_path / "site"
    folder.mkdir(exist_ok=True)
    marker = tmp_path / f"IMPORTED_{name}"
    (folder / f"{name}.py").write_text(
        f"open({str(marker)!r}, 'w').close()\n"
        "from lightning.pytorch import Callback\n\n\n"
        "class Evil(Callback):\n    pass\n",
        encoding="utf-8",
    )
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(folder), os.environ.get("PYTHONPATH", "")]))
    return marker


def _callback_recipe(tmp_path: Path, class_path: str, init_args: str = "{}") -> Path:
    path = tmp_path / "foreign.yaml"
    path.write_text(
        f"base: {SYNTHETIC}\ntrainer:\n  callbacks:\n"
        f"    - class_path: {class_path}\n      init_args: {init_args}\n",
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize("where", ["recipe", "inline", "model_option", "callback_option"])
def test_a_foreign_class_path_is_refused_before_import(where, tmp_path, monkeypatch, work, capsys):
    name = f"foreign_{where}"
    marker = _foreign_module(tmp_path, monkeypatch, name)
    args = {
        "recipe": ["--recipe", str(_callback_recipe(tmp_path, f"{name}.Evil"))],
        "inline": [
            "--recipe",
            SYNTHETIC,
            "--config",
            f"{{trainer: {{callbacks: [{{class_path: {name}.Evil}}]}}}}",
        ],
        "model_option": ["--recipe", SYNTHETIC, "--model", f"{name}.Evil"],
        "callback_option": ["--recipe", SYNTHETIC, f"--trainer.callbacks+={name}.Evil"],
    }[where]
    line = _refused(
        ["fit", *args], capsys, work, f"class path '{name}.Evil' is outside the project's modules"
    )
    assert f"--allow-import {name} or SM_ALLOW_IMPORT={name}" in line
    assert ", ".join(TRUSTED_MODULES) in line
    if where == "recipe":
        assert line.startswith(f"sm fit: error: {tmp_path / 'foreign.yaml'}: ")
    assert not marker.exists() and name not in sys.modules


@pytest.mark.parametrize("class_path", ["os.system", "subprocess.Popen", "builtins.exec", "posix.system"])
def test_the_deny_list_stays_refused(class_path, tmp_path, work, capsys):
    marker = tmp_path / "RAN"
    recipe = _callback_recipe(tmp_path, class_path, f"{{command: 'touch {marker}'}}")
    _refused(["fit", "--recipe", str(recipe)], capsys, work, f"class path '{class_path}' is outside")
    assert not marker.exists()


@pytest.mark.parametrize("opt_in", ["option", "option=", "environment"])
def test_an_explicit_opt_in_imports_the_module(opt_in, tmp_path, monkeypatch, work, capsys):
    name = {"option": "trusted_space", "option=": "trusted_equals", "environment": "trusted_env"}[opt_in]
    marker = _foreign_module(tmp_path, monkeypatch, name)
    recipe = _callback_recipe(tmp_path, f"{name}.Evil")
    extra = {"option": ["--allow-import", name], "option=": [f"--allow-import={name}"], "environment": []}[
        opt_in
    ]
    if opt_in == "environment":
        monkeypatch.setenv("SM_ALLOW_IMPORT", f"some_other_pkg, {name}")
    with pytest.raises(SystemExit) as exit_info:  # --print_config parses, prints and exits 0
        sm_main(["fit", *extra, "--recipe", str(recipe), "--print_config"])
    assert exit_info.value.code in (0, None)
    assert f"class_path: {name}.Evil" in capsys.readouterr().out
    assert marker.exists()
    # the policy is back as before: without the opt-in the same recipe is refused again
    monkeypatch.delenv("SM_ALLOW_IMPORT", raising=False)
    _refused(["fit", "--recipe", str(recipe)], capsys, work, f"class path '{name}.Evil' is outside")


class OutsideCallback(Callback):
    """A class of this test module, which is outside the policy's modules."""


def test_the_policy_holds_only_during_a_command(work, capsys):
    parser = jsonargparse.ArgumentParser(exit_on_error=False)
    parser.add_subclass_arguments(Callback, "cb")
    value = f"--cb={__name__}.OutsideCallback"
    with (
        import_policy(check_allowed_modules(())),
        pytest.raises(jsonargparse.ArgumentError, match="not allowed"),
    ):
        parser.parse_args([value])
    sm_main(["fit", "--recipe", str(work / "missing.yaml")])  # a command that installs and restores it
    capsys.readouterr()
    assert parser.parse_args([value]).cb.class_path == f"{__name__}.OutsideCallback"


def test_allow_import_arguments_are_split_off_and_checked(monkeypatch):
    monkeypatch.setenv("SM_ALLOW_IMPORT", "a.b, c,,")
    assert split_allow_import(["fit", "--allow-import", "x", "--recipe", "r", "--allow-import=y.z"]) == (
        ["fit", "--recipe", "r"],
        ("x", "y.z", "a.b", "c"),
    )
    with pytest.raises(InputError, match="needs a module name"):
        split_allow_import(["fit", "--allow-import"])
    for bad in ("a b", "1x", "jsonargparse", "jsonargparse._common", "x;import os"):
        with pytest.raises(InputError, match="--allow-import / SM_ALLOW_IMPORT"):
            check_allowed_modules((bad,))


def test_the_real_sm_refuses_then_imports_with_the_opt_in(tmp_path, monkeypatch):
    marker = _foreign_module(tmp_path, monkeypatch, "foreign_subprocess")
    recipe = _callback_recipe(tmp_path, "foreign_subprocess.Evil")
    work = tmp_path / "cwd"
    work.mkdir()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "ignore"}
    env.pop("SM_ALLOW_IMPORT", None)
    refused = subprocess.run(
        [sm_executable(), "fit", "--recipe", str(recipe)], cwd=work, env=env, capture_output=True, text=True
    )
    lines = refused.stderr.strip().splitlines()
    assert refused.returncode == 2 and len(lines) == 1 and "Traceback" not in refused.stderr, refused.stderr
    assert "class path 'foreign_subprocess.Evil' is outside" in lines[0]
    assert not marker.exists() and list(work.iterdir()) == []
    allowed = subprocess.run(
        [
            sm_executable(),
            "fit",
            "--recipe",
            str(recipe),
            "--allow-import",
            "foreign_subprocess",
            "--print_config",
        ],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
    )
    assert allowed.returncode == 0, allowed.stderr[-2000:]
    assert "LightningCLI's args parameter" not in allowed.stderr  # sys.argv and args agree
    assert marker.exists()


# --- files that are not recipes, refusals of jsonargparse -----------------------------------------


def test_base_etc_passwd_is_refused_without_printing_it(tmp_path, work, capsys):
    overlay = tmp_path / "overlay.yaml"
    overlay.write_text("base: /etc/passwd\n", encoding="utf-8")
    for args in (["--recipe", str(overlay)], ["--recipe", "/etc/passwd"], ["--config", "/etc/passwd"]):
        if not Path("/etc/passwd").is_file():
            pytest.skip("no /etc/passwd on this system")
        line = _refused(["fit", *args], capsys, work, "/etc/passwd: not a recipe (a YAML mapping")
        assert "root:" not in line and len(line) < 200


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        ("base: 3\n", "`base` names a recipe or a list of recipes, got int"),
        (
            "- a\n- b\n",
            "not a recipe (a YAML mapping of `key: value` lines is expected, the file holds a list)",
        ),
        (
            f"base: {SYNTHETIC}\nmodel:\n  init_args:\n    nonexistent_arg: 3\n",
            "Option 'nonexistent_arg' is not accepted",
        ),
        (f"base: {SYNTHETIC}\ntrainer:\n  max_epochs: [1, 2]\n", '"trainer.max_epochs": expected int'),
        (f"base: {SYNTHETIC}\ntrainer:\n  max_epochs: {'x' * 5000}\n", '"trainer.max_epochs": expected int'),
    ],
)
def test_jsonargparse_refusals_of_a_recipe_are_one_short_line_naming_it(
    content, expected, tmp_path, work, capsys
):
    recipe = tmp_path / "bad.yaml"
    recipe.write_text(content, encoding="utf-8")
    line = _refused(["fit", "--recipe", str(recipe)], capsys, work, expected)
    assert line.startswith(f"sm fit: error: {recipe}: ") and len(line) <= 500, line
    assert "usage:" not in line and "Subtypes" not in line


def test_a_checkpoints_refused_hyper_parameters_are_one_line_naming_it(tmp_path, work, capsys):
    path = tmp_path / "hp.ckpt"
    hparams = {"_class_path": "skeleton_mamba.tasks.recognition.module.ActionRecognitionModule", "lr": "fast"}
    torch.save({"state_dict": {}, "hyper_parameters": hparams}, path)
    line = _refused(["test", "--recipe", SYNTHETIC, "--ckpt_path", str(path)], capsys, work, str(path))
    assert "usage:" not in line and len(line) <= 500


# --- training-data errors -------------------------------------------------------------------------


def _annotation_recipe(tmp_path: Path, data: dict, **init_args) -> Path:
    ann = tmp_path / "ann.pkl"
    with open(ann, "wb") as f:  # not save_annotations, which refuses some of these cases itself
        pickle.dump(data, f, protocol=4)
    args = {
        "ann_file": str(ann),
        "num_classes": 3,
        "clip_len": 16,
        "batch_size": 8,
        "num_workers": 0,
        **init_args,
    }
    recipe = tmp_path / "real_data.yaml"
    recipe.write_text(
        f"base: {SYNTHETIC}\ntrainer: {{max_epochs: 1, logger: false, callbacks: null}}\n"
        "data:\n  class_path: skeleton_mamba.tasks.recognition.data.RecognitionDataModule\n"
        f"  init_args: {args}\n",
        encoding="utf-8",
    )
    return recipe


def _synthetic(**changes) -> dict:
    data = make_synthetic_annotations(num_classes=3, num_frames=32, seed=0)
    for key, value in changes.items():
        data["split"][key] = value
    return data


@pytest.mark.parametrize(
    ("case", "init_args", "expected"),
    [
        ("labels", {"num_classes": 2}, "labels outside [0, 2)"),
        ("joints", {"skeleton": "openpose18"}, "has samples with [25] joints; skeleton 'openpose18' has 18"),
        ("missing split", {"train_split": "xset_train"}, "no split 'xset_train'"),
        ("empty split", {}, "split 'xsub_train' is empty"),
        ("dangling split", {}, "split 'xsub_train' names 1 frame_dir without an annotation"),
    ],
)
def test_training_data_errors_are_one_line_naming_the_file(case, init_args, expected, tmp_path, work, capsys):
    changes = {"empty split": {"xsub_train": []}, "dangling split": {"xsub_train": ["nowhere"]}}.get(case, {})
    recipe = _annotation_recipe(tmp_path, _synthetic(**changes), **init_args)
    line = _refused(["fit", "--recipe", str(recipe)], capsys, work, expected)
    assert str(tmp_path / "ann.pkl") in line
