"""The T2M evaluation driver: replications of the protocol for the ground truth and a model.

As MDM ``eval/eval_humanml.py`` (``evaluation()``, ``evaluate_matching_score``, ``evaluate_fid``,
``evaluate_diversity``, ``evaluate_multimodality``) and ``CompMDMGeneratedDataset``. In each of
``repetitions`` replications (20), over the test clips drawn as :class:`~.evaluator_data.EvaluatorDataset`
does (random caption, random crop of a multiple of 4 frames, evaluator normalisation, zero padding to
196), in shuffled groups of ``batch_size`` (32, ``drop_last``):

- a *reference* pass embeds the real motions: the Gaussian every FID row is measured against;
- the *matching* pass embeds each group's captions and real motions (ground-truth row: R-Precision
  top-1/2/3, MM-Dist, FID vs the reference, Diversity) and, for the first ``ceil(samples / batch_size)``
  groups (MDM: 1000 samples -> 32 groups), generates one motion per caption at the real length, so the
  model row pairs each generated motion with its caption;
- MultiModality (when ``mm_samples`` > 0; MDM's ``mm`` modes: 100 captions x 30 generations, 10 pairs):
  ``mm_samples`` random test captions, ``mm_repeats`` generations each.

Generated features are de-normalised by the model, then normalised with the evaluator's statistics
(MDM ``renorm4t2m``). :func:`~.evaluation_report.summarize` turns the per-replication values into
``mean +- 1.96 std / sqrt(repetitions)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields

import numpy as np
import torch
from torch.utils.data import DataLoader
from tqdm.auto import tqdm

from skeleton_mamba.tasks.text2motion.evaluator import T2MEvaluator
from skeleton_mamba.tasks.text2motion.evaluator_data import EvaluatorDataset
from skeleton_mamba.tasks.text2motion.glove import HashedWordVectorizer, WordVectorizer
from skeleton_mamba.tasks.text2motion.humanml3d import MotionClip
from skeleton_mamba.tasks.text2motion.metrics import (
    R_PRECISION_BATCH,
    RPrecision,
    diversity,
    embedding_fid,
    multimodality,
)

__all__ = ["GROUND_TRUTH", "MODEL", "T2MEvalConfig", "T2MProtocol", "MotionGenerator", "T2MEvaluation"]

GROUND_TRUTH = "ground_truth"
MODEL = "model"

# captions (B), lengths (B), noise generator -> de-normalised features (B, >= max(lengths), 263)
MotionGenerator = Callable[[list[str], list[int], torch.Generator], torch.Tensor]


@dataclass(frozen=True)
class T2MProtocol:
    """Sizes of the protocol (defaults: MDM ``wo_mm``; MultiModality as its ``mm`` modes when enabled).

    Attributes:
        repetitions: replications (20).
        samples: generated motions per replication (1000); ``None`` = every full group of the test set.
        batch_size: R-Precision group size (32).
        diversity_times: random pairs of Diversity (300).
        mm_samples: captions for MultiModality (100 in MDM's mm modes); 0 skips it.
        mm_repeats: generations per caption (30).
        mm_times: random pairs per caption (10).
        seed: base seed; replication r draws crops, captions, order and noise from ``seed + r``.
    """

    repetitions: int = 20
    samples: int | None = 1000
    batch_size: int = R_PRECISION_BATCH
    diversity_times: int = 300
    mm_samples: int = 0
    mm_repeats: int = 30
    mm_times: int = 10
    seed: int = 0

    def check(self, num_clips: int) -> None:
        """Raise ``ValueError`` when the sizes cannot work on ``num_clips`` test clips."""
        groups = num_clips // self.batch_size
        if self.repetitions < 1 or groups < 1:
            raise ValueError(
                f"T2M evaluation needs repetitions >= 1 (got {self.repetitions}) and at least one group "
                f"of batch_size={self.batch_size} among the {num_clips} test clips"
            )
        generated = self.generated_groups(num_clips) * self.batch_size
        if min(generated, groups * self.batch_size) < self.diversity_times:
            raise ValueError(
                f"diversity_times={self.diversity_times} exceeds the {generated} generated / "
                f"{groups * self.batch_size} real motions per repetition: lower it or raise samples"
            )
        if self.mm_samples > 0 and (self.mm_repeats < self.mm_times or self.mm_samples > num_clips):
            raise ValueError(
                f"MultiModality needs mm_repeats ({self.mm_repeats}) >= mm_times ({self.mm_times}) and "
                f"mm_samples ({self.mm_samples}) <= the {num_clips} test clips"
            )

    def generated_groups(self, num_clips: int) -> int:
        """Groups generated per replication: ``ceil(samples / batch_size)``, at most all full groups."""
        groups = num_clips // self.batch_size
        return groups if self.samples is None else min(groups, math.ceil(self.samples / self.batch_size))


@dataclass(frozen=True)
class T2MEvalConfig(T2MProtocol):
    """The T2M evaluation of ``sm test``: the protocol's sizes (:class:`T2MProtocol`), the evaluator's files.

    Attributes:
        evaluator_checkpoint: the official ``finest.tar`` (comparable), a ``sm fit --recipe
            t2m_evaluator.yaml`` ``.ckpt`` (not comparable), or ``None``: a random evaluator (not comparable).
        evaluator_mean: the evaluator's Mean (MDM ``dataset/t2m_mean.npy``); needed with ``finest.tar``;
            default the data statistics.
        evaluator_std: the evaluator's Std (MDM ``dataset/t2m_std.npy``).
        glove_dir: folder of ``our_vab_*`` GloVe files; needed with an evaluator checkpoint; without it
            (random evaluator only) words get hashed random vectors.
    """

    evaluator_checkpoint: str | None = None
    evaluator_mean: str | None = None
    evaluator_std: str | None = None
    glove_dir: str | None = None

    @property
    def protocol(self) -> T2MProtocol:
        """The protocol's sizes alone."""
        return T2MProtocol(**{f.name: getattr(self, f.name) for f in fields(T2MProtocol)})


class T2MEvaluation:
    """Runs :class:`T2MProtocol` over test clips with an evaluator.

    Args:
        evaluator: the text and motion encoders.
        clips: test clips (de-normalised (T, 263) features with tokenised captions).
        words: GloVe word features (or the hashed stand-in).
        mean: (263,) evaluator statistics the motions are normalised with.
        std: (263,) evaluator statistics.
        protocol: the sizes.
    """

    def __init__(
        self,
        evaluator: T2MEvaluator,
        clips: list[MotionClip],
        words: WordVectorizer | HashedWordVectorizer,
        mean: np.ndarray,
        std: np.ndarray,
        protocol: T2MProtocol = T2MProtocol(),
    ) -> None:
        protocol.check(len(clips))
        self.evaluator = evaluator.eval()
        self.dataset = EvaluatorDataset(clips, mean, std, words)
        self.mean = torch.as_tensor(mean, dtype=torch.float32)
        self.std = torch.as_tensor(std, dtype=torch.float32)
        self.protocol = protocol

    @property
    def device(self) -> torch.device:
        return next(self.evaluator.parameters()).device

    def _embed_text(self, batch: dict) -> torch.Tensor:
        d = self.device
        return self.evaluator.embed_text(
            batch["word_embs"].to(d), batch["pos_onehot"].to(d), batch["cap_len"]
        )

    def _embed_motion(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        return self.evaluator.embed_motion(motion.to(self.device), lengths.to(self.device))

    def _normalise(self, features: torch.Tensor, lengths: torch.Tensor, frames: int) -> torch.Tensor:
        """De-normalised (B, T, 263) -> evaluator-normalised, zero past each length, padded to ``frames``."""
        features = features[:, :frames].float().cpu()
        motion = torch.zeros(features.shape[0], frames, features.shape[-1])
        motion[:, : features.shape[1]] = (features - self.mean) / self.std
        valid = torch.arange(frames)[None] < lengths[:, None]
        return motion * valid[..., None]

    def _generate(
        self,
        generate: MotionGenerator,
        captions: list[str],
        lengths: torch.Tensor,
        frames: int,
        noise: torch.Generator,
    ) -> torch.Tensor:
        features = generate(list(captions), lengths.tolist(), noise)
        return self._embed_motion(self._normalise(features, lengths, frames), lengths)

    @torch.no_grad()
    def run_once(self, repetition: int, generate: MotionGenerator | None, progress: bool = False) -> dict:
        """One replication: ``{"ground_truth": {metric: value}, "model": {...}}``.

        The model row exists only with ``generate``; everything is drawn from ``seed + repetition``.
        """
        p = self.protocol
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(p.seed + repetition)
            noise = torch.Generator().manual_seed(p.seed + repetition)
            loader = DataLoader(self.dataset, batch_size=p.batch_size, shuffle=True, drop_last=True)
            reference = torch.cat([self._embed_motion(b["motion"], b["length"]) for b in loader])
            groups = p.generated_groups(len(self.dataset)) if generate is not None else 0
            rows = {GROUND_TRUTH: ([], []), MODEL: ([], [])}
            bar = tqdm(loader, desc=f"T2M eval {repetition + 1}/{p.repetitions}", disable=not progress)
            for index, batch in enumerate(bar):
                text = self._embed_text(batch)
                rows[GROUND_TRUTH][0].append(text)
                rows[GROUND_TRUTH][1].append(self._embed_motion(batch["motion"], batch["length"]))
                if index < groups:
                    frames = batch["motion"].shape[1]
                    rows[MODEL][0].append(text)
                    rows[MODEL][1].append(
                        self._generate(generate, batch["caption"], batch["length"], frames, noise)
                    )
            results = {}
            for row, (texts, motions) in rows.items():
                if texts:
                    results[row] = self._scores(torch.cat(texts), torch.cat(motions), reference, noise)
            if generate is not None and p.mm_samples > 0:
                results[MODEL]["multimodality"] = self._multimodality(generate, noise)
        return results

    def _scores(
        self, text: torch.Tensor, motion: torch.Tensor, reference: torch.Tensor, noise: torch.Generator
    ) -> dict[str, float]:
        r_precision = RPrecision(batch_size=self.protocol.batch_size)
        r_precision.update(text.cpu(), motion.cpu())
        scores = {k: float(v) for k, v in r_precision.compute().items()}
        scores["fid"] = float(embedding_fid(reference.cpu(), motion.cpu()))
        scores["diversity"] = float(diversity(motion.cpu(), self.protocol.diversity_times, noise))
        return scores

    def _multimodality(self, generate: MotionGenerator, noise: torch.Generator) -> float:
        p = self.protocol
        chosen = torch.randperm(len(self.dataset))[: p.mm_samples].tolist()
        items = [self.dataset[i] for i in chosen]
        captions = [item["caption"] for item in items for _ in range(p.mm_repeats)]
        lengths = torch.tensor([item["length"] for item in items for _ in range(p.mm_repeats)])
        frames = items[0]["motion"].shape[0]
        embeddings = []
        for start in range(0, len(captions), p.batch_size):
            part = slice(start, start + p.batch_size)
            embeddings.append(self._generate(generate, captions[part], lengths[part], frames, noise))
        stacked = torch.cat(embeddings).reshape(p.mm_samples, p.mm_repeats, -1)
        return float(multimodality(stacked.cpu(), p.mm_times, noise))

    def run(
        self, generate: MotionGenerator | None, progress: bool = False
    ) -> dict[str, list[dict[str, float]]]:
        """All replications: ``{row: [per-replication {metric: value}]}``, rows ground truth and model."""
        per_row: dict[str, list[dict[str, float]]] = {}
        for repetition in range(self.protocol.repetitions):
            for row, scores in self.run_once(repetition, generate, progress).items():
                per_row.setdefault(row, []).append(scores)
        return per_row

    def describe(self) -> dict:
        """The protocol sizes and test-set size, for reports."""
        return {**asdict(self.protocol), "test_clips": len(self.dataset)}
