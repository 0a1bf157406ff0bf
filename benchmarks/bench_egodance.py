"""EgoDance benchmark: EMM (SkeletonMamba denoiser) vs an EDGE-style transformer denoiser of equal size.

Measures, side by side in one run: one training step (forward + losses + backward + AdamW) on a batch of
T-frame windows, and sampling one T-frame dance (T = 150 = 5 s at 30 fps) with DDIM (50 steps) and
DDPM (1000 steps), classifier-free guidance weight 2 (two denoiser calls per step). Both models use the
same music encoder (music-only condition, so the ResNet is not part of the timing); the transformer
baseline is EDGE's denoiser shape (reference dance.md section 6: self-attention over frames,
cross-attention to the condition + a time token, GELU, pre-norm) with its width chosen so that its
denoiser has the same parameter count as EMM's.

    python benchmarks/bench_egodance.py --json              # the seed's sizes (slow on a CPU)
    python benchmarks/bench_egodance.py --preset small --json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, median_ms  # noqa: E402

from skeleton_mamba import MixerConfig, SkeletonMambaConfig  # noqa: E402
from skeleton_mamba.tasks.diffusion import GaussianDiffusion, ddim_sample, ddpm_sample  # noqa: E402
from skeleton_mamba.tasks.egodance.encoders import MusicEncoder, sinusoidal_embedding  # noqa: E402
from skeleton_mamba.tasks.egodance.losses import emm_losses  # noqa: E402
from skeleton_mamba.tasks.egodance.model import EMM  # noqa: E402
from skeleton_mamba.tasks.egodance.representation import encode_motion  # noqa: E402

PRESETS = {
    "seed": dict(dim=128, depth=8, heads=4, mlp_dim=1024, context_dim=256, d_state=64, headdim=64, chunk=64),
    "small": dict(dim=32, depth=2, heads=2, mlp_dim=128, context_dim=64, d_state=16, headdim=16, chunk=32),
}


class TransformerDenoiser(nn.Module):
    """EDGE-style denoiser over frame vectors (B, T, 240) with cross-attention; same call as EMM."""

    def __init__(self, latent: int, depth: int, heads: int, context_dim: int, music: MusicEncoder):
        super().__init__()
        self.music_encoder = music
        self.null_context = nn.Parameter(torch.zeros(1, 1, context_dim))
        self.input_proj = nn.Linear(240, latent)
        self.time_mlp = nn.Sequential(nn.Linear(latent, 4 * latent), nn.SiLU(), nn.Linear(4 * latent, latent))
        self.cond_proj = nn.Linear(context_dim, latent)
        layer = nn.TransformerDecoderLayer(
            latent, heads, 2 * latent, 0.0, "gelu", batch_first=True, norm_first=True
        )
        self.decoder = nn.TransformerDecoder(layer, depth)
        self.output_proj = nn.Linear(latent, 240)

    def encode_condition(self, music, frames=None):
        return self.music_encoder(music)

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
    return sum(p.numel() for n, p in model.named_parameters() if not n.startswith("music_encoder"))


def build(preset: str) -> tuple[EMM, TransformerDenoiser]:
    p = PRESETS[preset]
    cfg = SkeletonMambaConfig(
        dim=p["dim"], depth=p["depth"], heads=p["heads"], mlp_dim=p["mlp_dim"],
        mixer=MixerConfig(d_state=p["d_state"], headdim=p["headdim"], chunk_size=p["chunk"]),
    )  # fmt: skip
    emm = EMM(cfg, context_dim=p["context_dim"], use_vision=False, heads=p["heads"], dropout=0.0)
    target = denoiser_params(emm)
    best = None
    for latent in range(8 * p["heads"], 4096, p["heads"]):
        music = MusicEncoder(35, p["context_dim"], 2, p["heads"], 512, 0.0)
        twin = TransformerDenoiser(latent, p["depth"], p["heads"], p["context_dim"], music)
        if best is None or abs(denoiser_params(twin) - target) < abs(denoiser_params(best) - target):
            best = twin
        if denoiser_params(twin) > target:
            break
    best.music_encoder.load_state_dict(emm.music_encoder.state_dict())
    return emm, best


def time_train_step(model, x0, music, diffusion, repeats: int) -> float:
    opt = torch.optim.AdamW(model.parameters(), lr=2e-4)

    def step():
        context = model.encode_condition(music)
        x_t, t, target = diffusion.training_pair(x0)
        loss = emm_losses(model(x_t, t, context), target)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()

    return median_ms(step, repeats=repeats)


def time_sampling(model, music, diffusion, sampler: str, steps: int) -> float:
    model.eval()
    with torch.no_grad():
        start = time.perf_counter()
        context = model.encode_condition(music)
        shape = (1, music.shape[1], 24, 10)
        if sampler == "ddim":
            ddim_sample(diffusion, model, shape, cond=context, sampling_steps=steps, guidance_weight=2.0)
        else:
            ddpm_sample(diffusion, model, shape, cond=context, guidance_weight=2.0)
    model.train()
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", choices=sorted(PRESETS), default="seed")
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ddim-steps", type=int, default=50)
    ap.add_argument("--ddpm-steps", type=int, default=1000, help="diffusion steps T (DDPM runs all of them)")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    emm, twin = build(args.preset)
    diffusion = GaussianDiffusion(args.ddpm_steps)
    x0 = encode_motion(
        0.3 * torch.randn(args.batch, args.frames, 24, 3), 0.1 * torch.randn(args.batch, args.frames, 3)
    )
    music = torch.randn(args.batch, args.frames, 35)
    result = {
        "machine": machine_info(),
        "threads": torch.get_num_threads(),
        "preset": args.preset,
        "batch": args.batch,
        "frames": args.frames,
        "guidance_weight": 2.0,
        "models": {},
    }
    for name, model in (("emm_skeleton_mamba", emm), ("edge_transformer", twin)):
        r = {"denoiser_params": denoiser_params(model)}
        r["train_step_ms"] = time_train_step(model, x0, music, diffusion, args.repeats)
        r[f"ddim{args.ddim_steps}_s"] = time_sampling(model, music[:1], diffusion, "ddim", args.ddim_steps)
        r[f"ddpm{args.ddpm_steps}_s"] = time_sampling(model, music[:1], diffusion, "ddpm", args.ddpm_steps)
        result["models"][name] = r
        if not args.json:
            print(name, r, flush=True)
    e, t = result["models"]["emm_skeleton_mamba"], result["models"]["edge_transformer"]
    result["ratios_emm_over_transformer"] = {k: e[k] / t[k] for k in e if k != "denoiser_params"}
    print(json.dumps(result, indent=2) if args.json else result["ratios_emm_over_transformer"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
