"""Why the text-to-motion demo does not show the everyday actions yet (issue 58, items 1 and 4): measured.

    python benchmarks/t2m_action_cause.py [--steps 150] [--json]

Two sides of the caption's path to the motion, each measured on the demo's own pieces:

- ``text``: the packaged sentence encoder (all-MiniLM-L6-v2) on the training captions of the seven actions
  (:data:`~skeleton_mamba.tasks.text2motion.actions.CAPTIONS`) and the demo's paraphrases: the cosine of the
  pooled embeddings within an action and between actions, and how many paraphrases lie nearest their own
  action's training captions (nearest centroid). The encoder carries the meaning when that is all of them.
- ``model``: the demo's tiny denoiser (``humanml3d_demo.yaml``'s module and backbone) trained on the actions
  (``SyntheticTextMotionDataModule(kinds=ACTIONS)``: 70 clips, batch 16, AdamW at the recipe's rate) for
  ``--steps`` steps, with the paper's cross-attention alone and with ``pooled_text`` ([MDM]'s summed sentence
  embedding) too. On the 14 held-out clips, at noise levels t: the x0 error with the clip's caption, with
  no caption and with another clip's caption, against the data's own variance (what predicting the mean
  scores; at t = T the input is pure noise, so only the caption can tell the action); and the share of the 14
  paraphrased prompts whose generated motion (DDIM 50, guidance 2.5, 6 s) shows its action
  (:func:`~skeleton_mamba.tasks.text2motion.actions.read_action`).

Writes ``benchmarks/t2m_action_cause.json`` with ``--json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, write_report  # noqa: E402

from skeleton_mamba.tasks.motion.formats.humanml3d_features import recover_from_ric  # noqa: E402
from skeleton_mamba.tasks.motion.synthetic.actions import ACTIONS  # noqa: E402
from skeleton_mamba.tasks.text2motion.actions import CAPTIONS, PARAPHRASES, read_action  # noqa: E402
from skeleton_mamba.tasks.text2motion.data import SyntheticTextMotionDataModule  # noqa: E402
from skeleton_mamba.tasks.text2motion.model import TextCondition  # noqa: E402
from skeleton_mamba.tasks.text2motion.module import TextToMotionModule  # noqa: E402
from skeleton_mamba.tasks.text2motion.synthetic import LABEL  # noqa: E402
from skeleton_mamba.tasks.text2motion.text_encoder import TextEncoder  # noqa: E402
from skeleton_mamba.tasks.training.recipe_resolution import packaged_recipe_dir  # noqa: E402

NOISE_LEVELS = (100, 500, 700, 900, 999)


def text_side() -> dict:
    """Pooled caption embeddings: cosine within / between actions, paraphrases' nearest action."""
    encoder = TextEncoder(None)

    def pooled(texts: list[str]) -> torch.Tensor:
        return torch.nn.functional.normalize(TextCondition(*encoder(texts)).pooled(), dim=-1)

    captions = [(a, LABEL + c) for a in ACTIONS for c in CAPTIONS[a]]
    asked = [(a, LABEL + p) for a in ACTIONS for p in PARAPHRASES[a]]
    cap, par = pooled([c for _, c in captions]), pooled([p for _, p in asked])
    labels = torch.tensor([ACTIONS.index(a) for a, _ in captions])
    same = labels[:, None] == labels[None]
    off_diagonal = ~torch.eye(len(cap), dtype=torch.bool)
    cosine = cap @ cap.T
    centroids = torch.stack([cap[labels == k].mean(0) for k in range(len(ACTIONS))])
    nearest = (par @ centroids.T).argmax(1).tolist()
    return {
        "cosine_within_action": round(float(cosine[same & off_diagonal].mean()), 3),
        "cosine_between_actions": round(float(cosine[~same].mean()), 3),
        "paraphrases_nearest_own_action": sum(ACTIONS[k] == a for k, (a, _) in zip(nearest, asked)),
        "paraphrases": len(asked),
    }


def demo_module(pooled_text: bool) -> TextToMotionModule:
    """``humanml3d_demo.yaml``'s module, its backbone fragment read as the recipe names it."""
    recipes = packaged_recipe_dir()
    args = dict(yaml.safe_load((recipes / "humanml3d_demo.yaml").read_text())["model"]["init_args"])
    args["backbone"] = yaml.safe_load((recipes / args["backbone"]).read_text())
    return TextToMotionModule(**args, pooled_text=pooled_text)


def model_side(steps: int, pooled_text: bool, seed: int = 0) -> dict:
    """Train the demo's model on the actions for ``steps`` steps; its x0 errors by noise level and the
    paraphrases' actions read back."""
    torch.manual_seed(seed)
    data = SyntheticTextMotionDataModule(
        train_clips=70, val_clips=14, batch_size=16, num_workers=0, kinds=ACTIONS
    )
    data.setup("fit")
    module = demo_module(pooled_text)
    module.set_data_statistics(data.training_statistics())
    optimizer = torch.optim.AdamW(module.denoiser.parameters(), lr=module.hparams.lr, weight_decay=0.0)
    started, losses, step = time.perf_counter(), [], 0
    while step < steps:
        for batch in data.train_dataloader():
            loss = module.loss(batch, module.hparams.cond_drop_prob)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            losses.append(loss.item())
            step += 1
            if step == steps:
                break
    train_s = time.perf_counter() - started
    module.eval()
    batch = next(iter(data.val_dataloader()))
    x0, mask = batch["motion"], batch["mask"]
    weights = mask[..., None].to(x0.dtype)

    def error(a: torch.Tensor) -> float:
        return round(float(((a - x0) ** 2 * weights).sum() / (weights.sum() * x0.shape[-1])), 3)

    cond = module.encode_text(batch["caption"])
    other = TextCondition(cond.tokens.roll(1, 0), cond.mask.roll(1, 0))
    generator = torch.Generator().manual_seed(seed)
    by_noise = {}
    with torch.no_grad():
        for t in NOISE_LEVELS:
            tt = torch.full((len(x0),), t)
            noise = torch.randn(x0.shape, generator=generator)
            x_t = module.diffusion.q_sample(x0, tt, noise)
            by_noise[str(t)] = {
                "caption": error(module.denoiser(x_t, tt, cond, mask)),
                "no_caption": error(module.denoiser(x_t, tt, cond.null(), mask)),
                "other_caption": error(module.denoiser(x_t, tt, other, mask)),
            }
    asked = [(a, LABEL + p) for a in ACTIONS for p in PARAPHRASES[a]]
    features, _ = module.generate(
        [p for _, p in asked], [120] * len(asked), generator=torch.Generator().manual_seed(seed + 2),
        sampler="ddim", sampling_steps=50, eta=0.0, guidance_weight=module.hparams.guidance_weight,
    )  # fmt: skip
    read = [read_action(j.numpy()) for j in recover_from_ric(features.double())]
    return {
        "pooled_text": pooled_text,
        "steps": steps,
        "train_s": round(train_s, 1),
        "last_50_loss": round(sum(losses[-50:]) / len(losses[-50:]), 4),
        "data_variance": error(torch.zeros_like(x0) + module.denoiser.skip_x0.data_mean),
        "x0_error_by_noise_level": by_noise,
        "paraphrases_shown": sum(r == a for (a, _), r in zip(asked, read)),
        "paraphrases": len(asked),
        "read": read,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=150)
    parser.add_argument("--json", action="store_true", help="write benchmarks/t2m_action_cause.json")
    args = parser.parse_args()
    report = {
        "machine": machine_info(),
        "text": text_side(),
        "model": [model_side(args.steps, pooled) for pooled in (False, True)],
    }
    print(report)
    if args.json:
        write_report(__file__, report)


if __name__ == "__main__":
    main()
