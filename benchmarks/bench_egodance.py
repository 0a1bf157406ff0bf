"""EgoDance benchmark: EMM (SkeletonMamba denoiser) vs an EDGE-style transformer denoiser of equal size.

Both models share the same condition path (music encoder + ResNet vision encoder + fusion module,
[EgoMusic] supp. Table 1), which is encoded ONCE per sample before the denoising loop; only the denoisers
differ. The transformer baseline is EDGE's denoiser shape (``model/model.py``: self-attention over frames,
cross-attention to the condition + a time token, GELU, pre-norm, 8 layers, 4 heads, feed-forward 2x)
with its width chosen so that its parameter count equals EMM's denoiser (encoders excluded).

Measured, side by side in one run (T = 150 frames = 5 s at 30 fps, classifier-free guidance weight 2
batched as one denoiser call on a doubled batch, ``torch.inference_mode``):

- ``train_step_ms``: forward + diffusion and kinematic losses + alignment loss + backward + AdamW on a
  batch; the frozen ResNet's pooled frame features are precomputed (cached), as a frozen backbone allows;
- ``condition_encode_s``: encoding one sample's music + frames + fusion (ResNet on all T frames);
- ``sample_step_ms``: the median time of one guided DDIM/DDPM denoising step;
- ``sample_step_gflop``: the matrix-product work of that step (``torch.utils.flop_counter``: mm, bmm,
  attention, convolutions; elementwise work is not counted), and the rate it ran at;
- ``ddim50_wall_s``: the real wall time of a full DDIM-50 run (condition encoding included; ``null`` when
  ``--max-run-s`` predicts it too long, ``ddim50_extrapolated_s`` = encoding + 50 x step is always given);
- ``ddpm1000_extrapolated_s``: ``sample_step_ms`` x 1000 + condition encoding: NOT a measured run;
- ``ddpm1000_wall_s`` (with ``--ddpm-run``): a real 1000-step DDPM run of one 150-frame sample as [EgoMusic]
  samples at test time (no classifier-free guidance), condition encoding included;
- ``gemm``: this machine's fp32 matrix-product rate timed in the same process (before and after the
  models), and ``*_fraction_of_gemm``: each model's achieved matrix-product rate as a fraction of it;
- ``--compile``: also the guided step of each denoiser compiled (``torch.compile``, inductor, weights
  frozen: ``skeleton_mamba/runtime/compiling.py``) in the same run: ``compiled_sample_step_ms``, its
  ``fraction_of_gemm``, ``compile_s`` (the first call) and ``compiled_max_abs_diff`` (against the
  eager step's output);
- ``gemm.bf16``: the same rate in bf16 (``torch.matmul`` of bf16 matrices);
- ``--bf16``: each denoiser's guided step in fp32 and under bf16 autocast (``sm dance --precision bf16``),
  alternately in one loop: both medians, the ratio and bf16's largest difference from the fp32 x0;
- ``--profile N``: the operators of one guided EMM sampling step by self CPU time (``torch.profiler``)
  and the share of it spent in matrix products.

    flock /tmp/bench.lock python benchmarks/bench_egodance.py --json              # paper sizes (slow on CPU)
    flock /tmp/bench.lock python benchmarks/bench_egodance.py --size tiny --json  # quick
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import warnings
from pathlib import Path

import torch
from torch import nn
from torch.utils.flop_counter import FlopCounterMode

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import gemm_gflop_per_s, machine_info, matmul_gflop, median_ms, operator_profile  # noqa: E402

from skeleton_mamba import MixerConfig, SkeletonMambaConfig  # noqa: E402
from skeleton_mamba.ssd.precision import inference_precision  # noqa: E402
from skeleton_mamba.tasks.egodance.encoders import sinusoidal_embedding  # noqa: E402
from skeleton_mamba.tasks.egodance.losses import alignment_loss, emm_losses  # noqa: E402
from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig  # noqa: E402
from skeleton_mamba.tasks.egodance.representation import encode_motion  # noqa: E402
from skeleton_mamba.tasks.egodance.sampling import CompiledDenoiser  # noqa: E402
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, ddim_sample, ddpm_sample  # noqa: E402
from skeleton_mamba.tasks.training.diffusion.samplers import guided_x0  # noqa: E402

SIZES = {
    # [EgoMusic] supp. Table 2 (D 128, Dc 256, N 8, 4 heads, MLP 1024, Transformer 512) + recipes/backbones
    "paper": dict(
        dim=128, depth=8, heads=4, mlp_dim=1024, context_dim=256, ff=512, d_state=64, headdim=64, chunk=64,
        group_paths=None, resnet=None, image_size=224,
    ),
    "small": dict(
        dim=32, depth=2, heads=2, mlp_dim=128, context_dim=64, ff=128, d_state=16, headdim=16, chunk=32,
        group_paths=None, image_size=64,
        resnet=dict(embedding_size=16, hidden_sizes=[16, 32], depths=[1, 1], layer_type="basic"),
    ),
    "tiny": dict(
        dim=16, depth=1, heads=2, mlp_dim=32, context_dim=16, ff=32, d_state=8, headdim=8, chunk=16,
        group_paths=[[1, 2, 0, 3, 4]], image_size=32,
        resnet=dict(embedding_size=8, hidden_sizes=[8, 16], depths=[1, 1], layer_type="basic"),
    ),
}  # fmt: skip
ENCODERS = ("music_encoder", "vision_encoder", "fusion")


class TransformerDenoiser(nn.Module):
    """EDGE-style x0 denoiser over frame vectors (B, T, 240) with cross-attention; EMM's call signature.

    The condition encoders are EMM's own modules (shared, not copied), so both models see the same c.
    """

    def __init__(self, latent: int, depth: int, heads: int, emm: EMM):
        super().__init__()
        self.encoders = [emm]  # a plain list: not registered, not counted, not trained twice
        context_dim = emm.context_dim
        self.null_context = nn.Parameter(torch.zeros(1, 1, context_dim))
        self.input_proj = nn.Linear(240, latent)
        self.time_mlp = nn.Sequential(nn.Linear(latent, 4 * latent), nn.SiLU(), nn.Linear(4 * latent, latent))
        self.cond_proj = nn.Linear(context_dim, latent)
        layer = nn.TransformerDecoderLayer(
            latent, heads, 2 * latent, 0.0, "gelu", batch_first=True, norm_first=True
        )
        self.decoder = nn.TransformerDecoder(layer, depth)
        self.output_proj = nn.Linear(latent, 240)

    def encode_modalities(self, music, frames=None):
        return self.encoders[0].encode_modalities(music, frames)

    def fuse(self, z_a, z_v):
        return self.encoders[0].fuse(z_a, z_v)

    def encode_condition(self, music, frames=None):
        return self.fuse(*self.encode_modalities(music, frames))

    def null_condition(self, context):
        return self.null_context.to(context.dtype).expand_as(context)

    def forward(self, x_t, t, context=None):
        b, n = x_t.shape[:2]
        if context is None:
            context = self.null_context.expand(b, n, -1)
        temb = self.time_mlp(sinusoidal_embedding(t, self.input_proj.out_features))
        h = self.input_proj(x_t.flatten(2)) + temb[:, None]
        pos = sinusoidal_embedding(torch.arange(n), h.shape[-1])
        memory = torch.cat([temb[:, None], self.cond_proj(context)], dim=1)
        return self.output_proj(self.decoder(h + pos, memory)).unflatten(2, (24, 10))


def denoiser_params(model: nn.Module) -> int:
    """Parameters outside the condition encoders."""
    return sum(p.numel() for n, p in model.named_parameters() if not n.startswith(ENCODERS))


def build(size: str) -> tuple[EMM, TransformerDenoiser]:
    """EMM at ``size`` and the transformer twin whose width gives the closest parameter count."""
    p = SIZES[size]
    cfg = SkeletonMambaConfig(
        dim=p["dim"], depth=p["depth"], heads=p["heads"], mlp_dim=p["mlp_dim"], group_paths=p["group_paths"],
        mixer=MixerConfig(d_state=p["d_state"], headdim=p["headdim"], chunk_size=p["chunk"]),
    )  # fmt: skip
    network = EMMConfig(
        context_dim=p["context_dim"],
        use_vision=True,
        resnet_layers=p["resnet"],
        heads=p["heads"],
        transformer_ff=p["ff"],
        dropout=0.0,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # random ResNet init: timing only
        emm = EMM(cfg, network, image_size=p["image_size"])
    target = denoiser_params(emm)
    h = p["heads"]

    def twin(units: int) -> TransformerDenoiser:
        return TransformerDenoiser(units * h, p["depth"], h, emm)

    lo, hi = 2, 2
    while denoiser_params(twin(hi)) < target:
        lo, hi = hi, hi * 2
    while hi - lo > 1:  # the parameter count grows with the width: bisect
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if denoiser_params(twin(mid)) < target else (lo, mid)
    best = min((twin(lo), twin(hi)), key=lambda m: abs(denoiser_params(m) - target))
    return emm, best


def time_train_step(
    model, x0, music, features, diffusion, repeats: int, warmup: int = 1
) -> tuple[float, float]:
    """One optimizer step's median ms and its matrix-product GFLOP; ``features`` (B, T, F) are the cached
    frozen-ResNet frame features."""
    emm = model.encoders[0] if isinstance(model, TransformerDenoiser) else model
    params = {id(p): p for p in model.parameters() if p.requires_grad}
    params.update({id(p): p for n, p in emm.named_parameters() if n.startswith(ENCODERS) and p.requires_grad})
    opt = torch.optim.AdamW(list(params.values()), lr=2e-4)
    model.train()

    def step():
        z_a = emm.music_encoder(music)
        z_v = emm.vision_encoder.mlp(features)
        context = emm.fuse(z_a, z_v)
        x_t, t, target = diffusion.training_pair(x0)
        loss = emm_losses(model(x_t, t, context), target)["loss"] + 0.01 * alignment_loss(z_a, z_v)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    return median_ms(step, repeats=repeats, warmup=warmup), matmul_gflop(step)


@torch.inference_mode()
def time_sampling(
    model,
    music,
    frames,
    diffusion,
    ddim_steps: int,
    step_repeats: int,
    max_run_s: float,
    ddpm_run: bool,
    compile: bool = False,
) -> dict:
    """Condition encoding, the median guided step, and a real full DDIM run, for one sample.

    The full run is skipped (``None``, with its extrapolation reported instead) when the measured steps
    predict it to exceed ``max_run_s``.
    """
    model.eval()
    start = time.perf_counter()
    context = model.encode_condition(music, frames)
    encode_s = time.perf_counter() - start
    shape = (1, music.shape[1], 24, 10)
    x = torch.randn(shape, device=music.device)
    step_ms, out = time_guided_step(model, x, context, diffusion, step_repeats)
    with FlopCounterMode(display=False) as counter:  # matrix products (mm, bmm, attention, conv)
        guided_x0(model, x, out[1], context, 2.0)
    step_gflop = counter.get_total_flops() / 1e9
    compiled = {}
    if compile:
        start = time.perf_counter()
        denoiser = CompiledDenoiser(model)
        got = guided_x0(denoiser, x, out[1], context, 2.0)  # compiles
        compiled["compile_s"] = time.perf_counter() - start
        ms, _ = time_guided_step(denoiser, x, context, diffusion, step_repeats)  # its 2nd call is slow too
        compiled.update(
            compiled_sample_step_ms=ms,
            compiled_sample_step_gflop_per_s=step_gflop / (ms / 1e3),
            compiled_over_eager=step_ms / ms,
            compiled_max_abs_diff=(got - out[0]).abs().max().item(),
        )
    ddim_estimate = encode_s + step_ms * ddim_steps / 1e3
    ddim_s = None
    if ddim_estimate <= max_run_s:
        start = time.perf_counter()
        context = model.encode_condition(music, frames)  # a full run encodes its condition once
        ddim_sample(
            diffusion,
            model,
            shape,
            cond=context,
            sampling_steps=ddim_steps,
            guidance_weight=2.0,
            device=music.device,
        )
        synchronize()
        ddim_s = time.perf_counter() - start
    ddpm_s = None
    if ddpm_run:  # [EgoMusic] at test time: all T steps, no classifier-free guidance
        start = time.perf_counter()
        context = model.encode_condition(music, frames)
        ddpm_sample(diffusion, model, shape, cond=context, device=music.device)
        synchronize()
        ddpm_s = time.perf_counter() - start
    return {
        "condition_encode_s": encode_s,
        "sample_step_ms": step_ms,
        "sample_step_gflop": step_gflop,
        "sample_step_gflop_per_s": step_gflop / (step_ms / 1e3),
        f"ddim{ddim_steps}_wall_s": ddim_s,
        f"ddim{ddim_steps}_extrapolated_s": ddim_estimate,
        f"ddpm{diffusion.num_steps}_extrapolated_s": encode_s + step_ms * diffusion.num_steps / 1e3,
        f"ddpm{diffusion.num_steps}_wall_s": ddpm_s,
        **compiled,
    }


def time_guided_step(denoiser, x, context, diffusion, repeats: int):
    """Median ms of guided steps at spread timesteps after one untimed call; (that, (the last output, its
    timestep))."""
    times = []
    for i in range(repeats + 1):
        t = torch.full((1,), diffusion.num_steps - 1 - 37 * i, dtype=torch.long, device=x.device)
        start = time.perf_counter()
        out = guided_x0(denoiser, x, t, context, 2.0)
        synchronize()
        times.append(time.perf_counter() - start)
    return statistics.median(times[1:]) * 1e3, (out, t)


def synchronize() -> None:
    if torch.cuda.is_available():
        torch.cuda.synchronize()


def fp32_and_bf16_step(model: nn.Module, music: torch.Tensor, frames: torch.Tensor, repeats: int) -> dict:
    """One guided denoising step (T frames, classifier-free guidance batched) in fp32 and under bf16 autocast
    (``sm dance --precision bf16``), called alternately ``repeats`` times after one untimed call each:
    median ms of both, the ratio fp32 over bf16, and bf16's largest difference from the fp32 x0 (absolute,
    and relative to the largest fp32 value)."""
    model.eval()
    with torch.inference_mode():
        context = model.encode_condition(music, frames)
        x = torch.randn(1, music.shape[1], 24, 10, device=music.device)
        t = torch.full((1,), 500, device=music.device)

        def run(precision: str) -> torch.Tensor:
            with inference_precision(precision, music.device.type):
                return guided_x0(model, x, t, context, 2.0)

        out = {p: run(p).float() for p in ("fp32", "bf16")}  # also the warm-up
        times: dict[str, list[float]] = {"fp32": [], "bf16": []}
        for _ in range(repeats):
            for p in times:
                start = time.perf_counter()
                run(p)
                times[p].append(1e3 * (time.perf_counter() - start))
    ms = {p: statistics.median(v) for p, v in times.items()}
    difference = float((out["bf16"] - out["fp32"]).abs().max())
    return {
        "fp32_ms": round(ms["fp32"], 2),
        "bf16_ms": round(ms["bf16"], 2),
        "fp32_over_bf16": round(ms["fp32"] / ms["bf16"], 2),
        "max_abs_difference": float(f"{difference:.3g}"),
        "max_relative_difference": float(f"{difference / float(out['fp32'].abs().max()):.3g}"),
        "repeats": repeats,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", choices=sorted(SIZES), default="paper")
    ap.add_argument("--batch", type=int, default=4, help="training batch")
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3, help="timed training steps (median)")
    ap.add_argument("--warmup", type=int, default=1, help="untimed training steps first")
    ap.add_argument("--step-repeats", type=int, default=5, help="timed sampling steps (median)")
    ap.add_argument("--ddim-steps", type=int, default=50)
    ap.add_argument("--diffusion-steps", type=int, default=1000, help="T (DDPM runs all of them)")
    ap.add_argument("--max-run-s", type=float, default=600.0, help="skip longer full DDIM runs")
    ap.add_argument("--no-train", action="store_true", help="skip the training step")
    ap.add_argument("--ddpm-run", action="store_true", help="also time a real full DDPM run (no CFG)")
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--json", action="store_true")
    ap.add_argument(
        "--compile",
        action="store_true",
        help="also time each denoiser's guided step compiled (torch.compile, weights frozen)",
    )
    ap.add_argument(
        "--bf16",
        action="store_true",
        help="also time each denoiser's guided step in fp32 and under bf16 autocast, alternately",
    )
    ap.add_argument(
        "--profile",
        type=int,
        default=0,
        metavar="N",
        help="print the N operators with the most self CPU time in one guided EMM sampling step "
        "(and the matrix products' share of it), then exit",
    )
    args = ap.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    device = torch.device(args.device)
    emm, twin = build(args.size)
    emm.to(device), twin.to(device)
    size = SIZES[args.size]["image_size"]
    diffusion = GaussianDiffusion(args.diffusion_steps).to(device)
    b, n = args.batch, args.frames
    x0 = encode_motion(0.3 * torch.randn(b, n, 24, 3), 0.1 * torch.randn(b, n, 3)).to(device)
    music = torch.randn(b, n, 35, device=device)
    frames = torch.rand(1, n, 3, size, size, device=device)
    with torch.inference_mode():  # the cached frozen-ResNet features of the training batch
        one = emm.vision_encoder.resnet(pixel_values=frames[0, :2]).pooler_output.flatten(1)
    features = torch.randn(b, n, one.shape[-1], device=device).abs()
    if args.profile:
        emm.eval()
        with torch.inference_mode():
            context = emm.encode_condition(music[:1], frames)
            x, t = torch.randn(1, n, 24, 10, device=device), torch.full((1,), 500, device=device)
            guided_x0(emm, x, t, context, 2.0)  # warm-up
            table, gemm_share = operator_profile(lambda: guided_x0(emm, x, t, context, 2.0), args.profile)
        print(f"{table}\nmatrix products: {100 * gemm_share:.0f} % of the self CPU time")
        return 0
    gemm_before = gemm_gflop_per_s()
    bf16_gemm = gemm_gflop_per_s(dtype=torch.bfloat16)
    result = {
        "machine": machine_info(),
        "threads": torch.get_num_threads(),
        "device": str(device),
        "size": args.size,
        "train_batch": b,
        "frames": n,
        "image_size": size,
        "guidance_weight": 2.0,
        "guidance": "classifier-free, cond + null batched as one denoiser call",
        "models": {},
    }
    for name, model in (("emm_skeleton_mamba", emm), ("edge_transformer", twin)):
        r = {"denoiser_params": denoiser_params(model)}
        if not args.no_train:
            r["train_step_ms"], r["train_step_gflop"] = time_train_step(
                model, x0, music, features, diffusion, args.repeats, args.warmup
            )
            r["train_step_gflop_per_s"] = r["train_step_gflop"] / (r["train_step_ms"] / 1e3)
        r.update(
            time_sampling(
                model,
                music[:1],
                frames,
                diffusion,
                args.ddim_steps,
                args.step_repeats,
                args.max_run_s,
                args.ddpm_run,
                args.compile,
            )
        )
        if args.bf16:
            r["bf16"] = fp32_and_bf16_step(model, music[:1], frames, args.step_repeats)
        result["models"][name] = r
        if not args.json:
            print(name, r, flush=True)
    result["gemm"] = {"before": gemm_before, "after": gemm_gflop_per_s(), "bf16": bf16_gemm}
    if not args.json:
        print(
            f"GEMM: fp32 {gemm_before['gflop_per_s']:.0f} GFLOP/s,"
            f" bf16 {bf16_gemm['gflop_per_s']:.0f} GFLOP/s"
        )
    for r in result["models"].values():
        for key in ("sample_step", "train_step", "compiled_sample_step"):
            if f"{key}_gflop_per_s" in r:
                r[f"{key}_fraction_of_gemm"] = r[f"{key}_gflop_per_s"] / gemm_before["gflop_per_s"]
    e, t = result["models"]["emm_skeleton_mamba"], result["models"]["edge_transformer"]
    result["ratios_emm_over_transformer"] = {
        k: e[k] / t[k]
        for k in e
        if k not in ("denoiser_params", "condition_encode_s", "compiled_max_abs_diff", "bf16")
        and e[k] is not None
        and t.get(k) is not None
    }
    print(json.dumps(result, indent=2) if args.json else result["ratios_emm_over_transformer"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
