"""``sm fit|validate|test|predict`` (LightningCLI) with ``--recipe``, and ``sm recipes``.

Parse-level behaviour runs in-process through ``skeleton_mamba.tasks.training.cli.main`` (the console script's
function); training runs go through the real ``sm`` executable in a subprocess.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest
import yaml

import skeleton_mamba.tasks.training.lightning_cli  # noqa: F401  (Lightning's log handler binds stderr at import)
from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.training.cli import main as sm_main
from skeleton_mamba.tasks.training.recipe_resolution import (
    packaged_recipes,
    recipe_description,
    resolve_recipe,
)
from tests.helpers.sm import run_sm

RECIPES_DIR = Path(__file__).resolve().parents[2] / "recipes"
EXPECTED_RECIPES = {
    "ntu60.yaml",
    "ntu60_xview.yaml",
    "ntu120_xsub.yaml",
    "ntu120_xset.yaml",
    "kinetics.yaml",
    "recognition_synthetic.yaml",
}


def print_config(args: list[str], capsys) -> dict:
    with pytest.raises(SystemExit) as exit_info:
        sm_main([*args, "--print_config"])
    assert exit_info.value.code in (0, None)
    return yaml.safe_load(capsys.readouterr().out)


# --- recipe resolution --------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["recognition_synthetic.yaml", "recognition_synthetic_causal.yaml"])
def test_synthetic_recognition_keeps_the_lowest_validation_loss(name):
    """The generated classes are separable: top-1 is 1.0 after an epoch, and ModelCheckpoint keeps the first
    of tied scores, so monitoring top-1 kept an almost untrained model (best-epoch=000)."""
    callbacks = yaml.safe_load((RECIPES_DIR / name).read_text())["trainer"]["callbacks"]
    best = [c["init_args"] for c in callbacks if "monitor" in c.get("init_args", {})]
    assert best == [{"monitor": "val/loss", "mode": "min", "save_top_k": 1, "filename": "best-{epoch:03d}"}]


def test_packaged_recipes_are_the_top_level_yaml_files():
    on_disk = {p.name for p in RECIPES_DIR.glob("*.yaml")}
    assert set(packaged_recipes()) == on_disk
    assert EXPECTED_RECIPES <= on_disk
    assert "skeleton_mamba.yaml" not in packaged_recipes()  # backbones/ holds fragments, not recipes


def test_resolve_recipe_name_suffixless_name_path_and_unknown(tmp_path):
    assert resolve_recipe("ntu60.yaml") == RECIPES_DIR / "ntu60.yaml"
    assert resolve_recipe("ntu60") == RECIPES_DIR / "ntu60.yaml"
    local = tmp_path / "ntu60.yaml"  # an existing path wins over the packaged name
    local.write_text("# mine\ntrainer: {max_epochs: 1}\n")
    assert resolve_recipe(str(local)) == local
    assert resolve_recipe("no_such_recipe.yaml") is None


def test_recipe_description_is_the_leading_comment(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text("\n#   Trains a thing  \n# second line\ntrainer: {}\n")
    assert recipe_description(path) == "Trains a thing"
    path.write_text("trainer: {}\n# late comment\n")
    assert recipe_description(path) == ""


def test_sm_recipes_lists_each_recipe_with_its_first_comment_line(capsys):
    assert sm_main(["recipes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    listed = {line.split()[0]: line.split(None, 1)[1] for line in lines}
    assert set(listed) == {p.name for p in RECIPES_DIR.glob("*.yaml")}
    for name, description in listed.items():
        first = (RECIPES_DIR / name).read_text().splitlines()[0]
        assert first.startswith("# ") and description == first[2:].strip()
        # a whole statement, not the first line of a sentence cut mid-way
        assert description.count("(") == description.count(")"), f"{name}: unclosed '(' in {description!r}"
        last_word = description.rstrip(".").split()[-1].lower()
        dangling = {"the", "a", "and", "of", "for"}
        assert not description.endswith((",", ";", ":")) and last_word not in dangling, name


# --- parsing: names, paths, merge order, links ----------------------------------------------------


def test_print_config_recipe_name_and_path_agree_and_compose_the_backbone(capsys):
    by_name = print_config(["fit", "--recipe", "ntu60.yaml"], capsys)
    by_path = print_config(["fit", "--recipe", str(RECIPES_DIR / "ntu60.yaml")], capsys)
    assert by_name == by_path
    # the backbone file states only what differs from SkeletonMambaConfig's defaults: [EgoMusic]'s sizes
    backbone_file = yaml.safe_load((RECIPES_DIR / "backbones" / "skeleton_mamba.yaml").read_text())
    backbone = by_name["model"]["init_args"]["backbone"]
    defaults = SkeletonMambaConfig()
    for key in ("dim", "depth", "heads", "mlp_dim"):
        assert backbone[key] == backbone_file.get(key, getattr(defaults, key))
    # [EgoMusic] supp. Table 2
    assert (backbone["dim"], backbone["depth"], backbone["mlp_dim"]) == (128, 8, 1024)
    # Linked values are not options: they come from the data module at instantiation.
    assert "num_classes" not in by_name["model"]["init_args"]
    assert by_name["data"]["init_args"]["num_classes"] == 60


def test_config_files_and_dotted_overrides_merge_left_to_right(tmp_path, capsys):
    extra = tmp_path / "extra.yaml"
    extra.write_text("trainer: {max_epochs: 5}\nmodel: {init_args: {lr: 0.5}}\n")
    base = ["fit", "--recipe", "recognition_synthetic.yaml"]
    later_override = print_config([*base, "--config", str(extra), "--trainer.max_epochs", "3"], capsys)
    assert later_override["trainer"]["max_epochs"] == 3
    assert later_override["model"]["init_args"]["lr"] == 0.5
    later_file = print_config([*base, "--trainer.max_epochs", "3", "--config", str(extra)], capsys)
    assert later_file["trainer"]["max_epochs"] == 5
    short_form = print_config([*base, "--model.lr", "0.7", "--data.batch_size", "4"], capsys)
    assert short_form["model"]["init_args"]["lr"] == 0.7
    assert short_form["data"]["init_args"]["batch_size"] == 4


def test_unknown_recipe_is_a_parser_error_listing_the_recipes(capsys):
    assert sm_main(["fit", "--recipe", "no_such_recipe.yaml"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sm fit: error: --recipe 'no_such_recipe.yaml': no such file"), err
    assert err.count("\n") == 1, err
    assert "Available recipes" in err and "usage:" not in err
    assert all(name in err for name in EXPECTED_RECIPES)
    assert "Traceback" not in err


def test_missing_dataset_stops_with_where_it_goes_and_how_to_build_it(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    missing = tmp_path.resolve() / "data" / "ntu60_3danno.pkl"  # the recipe's path, relative to the cwd
    assert sm_main(["fit", "--recipe", "ntu60.yaml"]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err
    assert "sm prepare ntu60 --raw" in err
    assert "Traceback" not in err


# --- real runs through the console script -------------------------------------------------------


def test_sm_fit_fast_dev_run_on_the_synthetic_recipe(tmp_path):
    result = run_sm(
        ["fit", "--recipe", "recognition_synthetic.yaml", "--trainer.fast_dev_run", "true"], tmp_path
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Running in `fast_dev_run` mode" in result.stdout + result.stderr
    assert "Traceback" not in result.stderr


def test_a_fit_that_trains_nothing_leaves_no_run_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["fit", "--recipe", "recognition_synthetic.yaml", "--data.init_args.batch_size=1000"]
    assert sm_main([*args, "--trainer.max_epochs=1", "--trainer.enable_progress_bar=false"]) == 2
    assert "the training data gives no batch" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()  # neither runs/<name>/version_0 nor an empty runs/<name>/


def test_sm_fit_ddp_over_two_cpu_processes(tmp_path):
    result = run_sm(
        [
            "fit", "--recipe", "recognition_synthetic.yaml",
            "--trainer.accelerator", "cpu", "--trainer.devices", "2", "--trainer.strategy", "ddp",
            "--trainer.max_epochs", "1", "--trainer.enable_progress_bar", "false",
            "--data.train_per_class", "8", "--data.val_per_class", "4", "--trainer.num_sanity_val_steps", "0",
            "--trainer.enable_model_summary", "false",
        ],
        tmp_path,
    )  # fmt: skip
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-3000:]
    assert "GLOBAL_RANK: 1, MEMBER: 2/2" in output  # the second process joined (gloo on CPU)
    # Global batch 2 x 8 = 16 -> lr = 0.02 * 16 / 8 (recipe: lr 0.02 per base batch 8).
    lr = float(re.search(r"SGD learning rate ([0-9.e-]+)", output).group(1))
    assert lr == pytest.approx(0.04)
    run_dir = tmp_path / "runs" / "recognition_synthetic" / "version_0"
    assert (run_dir / "checkpoints" / "last.ckpt").is_file()
    assert (run_dir / "config.yaml").is_file() and (run_dir / "metrics.csv").is_file()
    assert not (tmp_path / "runs" / "recognition_synthetic" / "version_1").exists()  # TB and CSV share a dir


def test_image_size_and_fps_are_linked_from_the_data_module():
    from lightning.pytorch import LightningDataModule, LightningModule

    from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI, import_task_modules

    import_task_modules()
    data = ["--data.init_args.image_size", "48", "--data.init_args.fps", "20"]
    args = ["--config", "egodance_demo.yaml", *data, "--model.init_args.head_guidance.source", "none"]
    args += ["--trainer.logger", "false"]
    with pytest.warns(UserWarning, match="randomly initialised"):
        cli = SkeletonMambaCLI(
            LightningModule, LightningDataModule, subclass_mode_model=True, subclass_mode_data=True,
            run=False, args=args,
        )  # fmt: skip
    assert (cli.model.hparams.image_size, cli.model.hparams.fps) == (48, 20)
    assert cli.model.model.vision_encoder.image_size == 48
    recipe = yaml.safe_load((RECIPES_DIR / "egodance_demo.yaml").read_text())["model"]["init_args"]
    assert "image_size" not in recipe and "fps" not in recipe  # stated once, on the data module


def test_qean_window_lengths_are_linked_from_the_data_module(tmp_path):
    """``seed_frames``, ``music_frames``, ``predict_frames`` reach ``network`` (a nested link target),
    ``generate_frames`` the module, from the data module alone."""
    from lightning.pytorch import LightningDataModule, LightningModule

    from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI, import_task_modules

    import_task_modules()
    for folder in ("motions", "music"):  # the AIST++ layout the data module checks at construction
        (tmp_path / folder).mkdir()
    lengths = {"seed_frames": 12, "music_frames": 24, "predict_frames": 4, "generate_frames": 20}
    args = ["--config", "qean.yaml", f"--data.init_args.root={tmp_path}", "--trainer.logger", "false"]
    args += [f"--data.init_args.{k}={v}" for k, v in lengths.items()]
    args += ["--model.init_args.network.hidden=32", "--model.init_args.network.heads=2"]
    cli = SkeletonMambaCLI(
        LightningModule, LightningDataModule, subclass_mode_model=True, subclass_mode_data=True,
        run=False, args=args,
    )  # fmt: skip
    config = cli.model.model.config
    assert (config.seed_frames, config.music_frames, config.predict_frames) == (12, 24, 4)
    assert config.hidden == 32 and cli.model.hparams.generate_frames == 20
    assert cli.model.hparams["network"]["seed_frames"] == 12  # what the checkpoint will hold
    assert cli.model.test_evaluation.protocol.seed_frames == 12
    recipe = yaml.safe_load((RECIPES_DIR / "qean.yaml").read_text())["model"]["init_args"]
    assert not set(lengths) & (set(recipe) | set(recipe["network"]))  # stated once, on the data module


@pytest.mark.parametrize(
    "recipe, data_module, encoder",
    [
        ("egodance_demo.yaml", "egodance.data", lambda m: m.model.music_encoder.proj),
        ("qean.yaml", "qean.data", lambda m: m.model.audio_embed.linear),
        ("stream_dance_demo.yaml", "stream.data", None),
    ],
)
def test_music_width_is_linked_from_the_data_module(recipe, data_module, encoder, tmp_path, monkeypatch):
    """The music width is the data module's (``music_dim``); the model receives it, no recipe states it."""
    monkeypatch.chdir(tmp_path)
    import importlib
    import warnings

    from lightning.pytorch import LightningDataModule, LightningModule

    from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI, import_task_modules

    import_task_modules()
    data = importlib.import_module(f"skeleton_mamba.tasks.{data_module}")
    constant = "NUM_FEATURES" if data_module == "stream.data" else "NUM_MUSIC_FEATURES"
    monkeypatch.setattr(data, constant, 7)
    for folder in ("motions", "music"):  # the AIST++ layout qean's data module checks at construction
        (tmp_path / folder).mkdir()
    args = ["--config", recipe, "--trainer.logger", "false"]
    if recipe == "qean.yaml":
        args += [f"--data.init_args.root={tmp_path}", "--model.init_args.network.hidden=32"]
        args += ["--model.init_args.network.heads=2"]
    if recipe == "egodance_demo.yaml":
        args += ["--model.init_args.head_guidance.source", "none"]
    if data_module == "stream.data":
        args += ["--data.init_args.beat_phase", "false"]  # 34 features (7 here), without the 2 of the phase
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the demo's random ResNet
        cli = SkeletonMambaCLI(
            LightningModule, LightningDataModule, subclass_mode_model=True, subclass_mode_data=True,
            run=False, args=args,
        )  # fmt: skip
    assert cli.datamodule.music_dim == 7
    if encoder is None:  # the streaming dancer: pose channels + music features per joint token
        assert cli.model.hparams.music_dim == 7 and cli.model.model.music_mean.shape == (7,)
    else:
        assert cli.model.hparams["network"]["music_dim"] == 7 and encoder(cli.model).in_features == 7
    init = yaml.safe_load((RECIPES_DIR / recipe).read_text())["model"]["init_args"]
    assert "music_dim" not in init and "music_dim" not in (init.get("network") or {})


def test_overlay_recipes_are_their_base_with_their_own_keys(capsys):
    base = print_config(["fit", "--recipe", "ntu60.yaml"], capsys)
    overlay = print_config(["fit", "--recipe", "ntu120_xsub.yaml"], capsys)
    data = overlay["data"]["init_args"]
    assert (data["num_classes"], data["ann_file"]) == (120, "data/ntu120_3danno.pkl")
    assert (data["train_split"], data["val_split"]) == ("xsub_train", "xsub_val")
    assert [logger["init_args"]["name"] for logger in overlay["trainer"]["logger"]] == ["ntu120_xsub"] * 2
    assert overlay["trainer"]["callbacks"] == base["trainer"]["callbacks"]  # not in the overlay: the base's
    assert overlay["model"] == base["model"] and overlay["trainer"]["max_epochs"] == 80
    mamba = print_config(["fit", "--recipe", "qean_mamba.yaml"], capsys)
    assert mamba["model"]["init_args"]["backbone"]["dim"] == 128  # a path relative to the overlay's folder
    assert mamba["model"]["init_args"]["network"]["hidden"] == 800 and mamba["trainer"]["max_steps"] == 500000
    paper = print_config(["fit", "--recipe", "egodance.yaml"], capsys)
    fast = print_config(["fit", "--recipe", "egodance_fast.yaml"], capsys)
    own = {"loss": {"cond_drop_prob": 0.25}, "sampling": {"sampler": "ddim", "sampling_steps": 50}}
    own["sampling"]["guidance_weight"] = 2.0
    model = paper["model"]["init_args"]
    assert all({k: model[group][k] for k in keys} != keys for group, keys in own.items())
    for group, keys in own.items():
        model[group] |= keys
    assert [logger["init_args"]["name"] for logger in fast["trainer"].pop("logger")] == ["egodance_fast"] * 2
    assert [logger["init_args"]["name"] for logger in paper["trainer"].pop("logger")] == ["egodance"] * 2
    assert fast == paper  # the rest of the model, the trainer (callbacks, clipping), the data: the base's


def test_overlay_of_a_local_recipe_by_relative_path_and_base_errors(tmp_path, capsys):
    (tmp_path / "mine.yaml").write_text("base: recognition_synthetic.yaml\ntrainer: {max_epochs: 7}\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "more.yaml").write_text("base: ../mine.yaml\nmodel: {init_args: {lr: 0.25}}\n")
    config = print_config(["fit", "--recipe", str(tmp_path / "sub" / "more.yaml")], capsys)
    assert config["trainer"]["max_epochs"] == 7 and config["model"]["init_args"]["lr"] == 0.25
    assert config["data"]["class_path"].endswith("SyntheticRecognitionDataModule")
    (tmp_path / "loop.yaml").write_text("base: loop.yaml\n")
    (tmp_path / "missing.yaml").write_text("base: no_such_base.yaml\n")
    for name, message in (("loop.yaml", "include itself"), ("missing.yaml", "'no_such_base.yaml'")):
        assert sm_main(["fit", "--recipe", str(tmp_path / name), "--print_config"]) == 2
        err = capsys.readouterr().err
        assert message in err and name in err and err.count("\n") == 1, err


def test_the_trainer_method_gets_weights_only_true(tmp_path, monkeypatch):
    """Lightning's own load of ``--ckpt_path`` is restricted to weights (``weights_only=True``)."""
    from lightning.pytorch import LightningDataModule, LightningModule

    from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI, import_task_modules

    received: dict = {}

    class RecordingCLI(SkeletonMambaCLI):
        def before_fit(self) -> None:  # LightningCLI's hook: the trainer method is looked up after it
            self.trainer.fit = lambda **kwargs: received.update(kwargs)

    import_task_modules()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["sm"])  # the arguments are passed as args=
    args = ["fit", "--recipe", "recognition_synthetic.yaml", "--trainer.logger", "false"]
    RecordingCLI(
        LightningModule, LightningDataModule, subclass_mode_model=True, subclass_mode_data=True, args=args,
        save_config_callback=None,
    )  # fmt: skip
    assert received["weights_only"] is True and received["ckpt_path"] is None
    assert isinstance(received["model"], LightningModule)
