"""Does the live dancer follow the music? Its beat against chance on songs it never heard, and in silence.

    python benchmarks/bench_conditioning.py --runs RUN... [--songs FILE...] [--seconds 30] [--json]

For each trained ``stream_dance_demo.yaml`` run (its log folder: ``checkpoints/last.ckpt`` and the demo's
held-out music ``demo/*_dance.wav`` with its truth ``demo/*_reference.npz``) and each song (default: the
held-out synthetic track and the real recordings of ``../shared/data/music``), the dancer dances as ``sm
stream`` does (:class:`~skeleton_mamba.tasks.stream.live.LiveDancer`, frame by frame on its own poses), then
again to silence of the same length (the music removed: what the network does from its own previous poses
alone). Each dance is scored on the song's beats (librosa's tracker at 30 fps):

- ``margin``: Bailando's BeatAlign minus its chance, the same dance scored against the beat grid shifted by
  1/10 ... 9/10 of a beat (:func:`~skeleton_mamba.tasks.motion.metrics.beat_align.beat_align_over_chance`);
  0 means no relation to the beat. The dance to silence, scored on the song's beats, is the margin a dance
  that cannot hear the song gets;
- ``blocks``: pose amplitude (root-relative joint positions' standard deviation, mean over joints, m) per 5 s
  block, and ``freeze_ratio``, the smallest block from 10 s on over the largest (freezing: < 0.4);
- ``tilt_deg``: mean angle of the torso (pelvis to neck) from vertical, beside the held-out truth's;
- ``lagged_margins``: the margin against the beats delayed by 0, 1, ... frames up to a beat period, and its
  best lag: a dance on the beat but late (the output's causal low-pass delays it by ``filter_delay_frames``,
  ``stages d / (1 - d)``) peaks there;
- per run, ``teacher_forced_loss``: the training loss on the validation windows with their own music,
  another window's, and the training mean (how much the next pose leans on the music).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import librosa
import numpy as np
import torch
import torch.nn.functional as F
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, write_report  # noqa: E402

from skeleton_mamba.tasks.motion.formats.fact_features import features_to_joints  # noqa: E402
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion  # noqa: E402
from skeleton_mamba.tasks.motion.metrics.beat_align import beat_align_over_chance  # noqa: E402
from skeleton_mamba.tasks.stream.data import StreamDanceDataModule  # noqa: E402
from skeleton_mamba.tasks.stream.features import FPS, HOP, SR  # noqa: E402
from skeleton_mamba.tasks.stream.live import LiveDancer  # noqa: E402
from skeleton_mamba.tasks.stream.model import teacher_forcing_inputs, tokens_to_features  # noqa: E402
from skeleton_mamba.tasks.stream.module import StreamDanceModule  # noqa: E402
from skeleton_mamba.tasks.training.pretrained import load_module_from  # noqa: E402

SHARED_MUSIC = Path(__file__).resolve().parents[2] / "shared" / "data" / "music"
BLOCK_SECONDS = 5.0
PELVIS, NECK = 0, 12  # SMPL-24


def dance(model, audio: np.ndarray) -> np.ndarray:
    """The live dancer's (T, 24, 3) joints (m) for mono audio at :data:`SR`, as ``sm stream`` dances."""
    dancer = LiveDancer(model, SR)
    with torch.no_grad():
        dancer.push(audio.astype(np.float32), last=True)
        return features_to_joints(tokens_to_features(dancer.tokens().double())).numpy()


def music_beats(audio: np.ndarray) -> np.ndarray:
    """Beat frames at 30 fps (librosa's tracker; one hop of 512 samples at 15360 Hz is one frame)."""
    _, beats = librosa.beat.beat_track(y=audio, sr=SR, hop_length=HOP)
    return np.asarray(beats, dtype=np.int64)


def blocks(joints: np.ndarray) -> list[float]:
    """Pose amplitude per 5 s block: std over the block's frames of root-relative joints, mean over joints."""
    relative = joints - joints[:, PELVIS : PELVIS + 1]
    size = int(BLOCK_SECONDS * FPS)
    return [float(relative[i : i + size].std(axis=0).mean()) for i in range(0, len(joints) - size + 1, size)]


def tilt_deg(joints: np.ndarray) -> float:
    """Mean angle (degrees) between the pelvis-to-neck vector and vertical (+y)."""
    torso = joints[:, NECK] - joints[:, PELVIS]
    cos = torso[:, 1] / np.linalg.norm(torso, axis=1).clip(1e-9)
    return float(np.degrees(np.arccos(cos.clip(-1, 1))).mean())


def lagged_margins(joints: np.ndarray, beats: np.ndarray) -> list[float]:
    """The margin over chance against the beats delayed by 0, 1, ... frames, up to one beat period: a dance
    that moves on the beat but late peaks at its lag."""
    period = int(round(float(np.median(np.diff(beats))))) if len(beats) > 2 else 0
    margins = []
    for lag in range(period):
        late = beats[beats + lag < len(joints)] + lag
        align, chance = beat_align_over_chance(joints, late, "bailando", FPS)
        margins.append(align - chance)
    return margins


def score(joints: np.ndarray, beats: np.ndarray) -> dict:
    align, chance = beat_align_over_chance(joints, beats, "bailando", FPS)
    amplitude = blocks(joints)
    late = amplitude[2:]  # from 10 s on
    lagged = lagged_margins(joints, beats)
    return {
        "beat_align": align, "chance": chance, "margin": align - chance, "blocks": amplitude,
        "freeze_ratio": min(late) / max(amplitude) if late else None, "tilt_deg": tilt_deg(joints),
        "lagged_margins": lagged, "best_lag_frames": int(np.argmax(lagged)) if lagged else None,
    }  # fmt: skip


def table(report: dict) -> str:
    """The markdown table of ``benchmarks/README.md`` from a report (``--table`` prints it)."""
    lines = [
        "| seed | song | margin to the song | margin in silence (song's beats) | truth's margin | "
        "best margin against late beats (lag); silence's | smallest 5 s block from 10 s / largest | "
        "torso tilt (truth) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for results in sorted(report["runs"].values(), key=lambda r: r["seed"]):
        for song, entry in results.items():
            if not isinstance(entry, dict) or "music" not in entry:
                continue
            music, silence = entry["music"], entry["silence"]
            truth = f"{entry['truth']['margin']:+.3f}" if "truth" in entry else ""
            quiet = max(silence["lagged_margins"], default=float("nan"))
            lines.append(
                f"| {results['seed']} | {song} ({entry['kind']}) | {music['margin']:+.3f} | "
                f"{silence['margin']:+.3f} | {truth} | {_lagged(music)}; silence {quiet:+.3f} | "
                f"{_ratio(music['freeze_ratio'])} | {music['tilt_deg']:.1f} deg "
                f"({results['truth']['tilt_deg']:.1f}) |"
            )
    lines += [
        "",
        "| seed | output low-pass delay | teacher-forced loss: own music | another window's music | "
        "the music's training mean |",
        "|---|---|---|---|---|",
    ]
    for results in sorted(report["runs"].values(), key=lambda r: r["seed"]):
        loss = results["teacher_forced_loss"]
        own, other, mean = loss["own music"], loss["another window's music"], loss["mean music"]
        lines.append(
            f"| {results['seed']} | {results['filter_delay_frames']:.0f} frames | {own:.4f} | "
            f"{other:.4f} (x{other / own:.2f}) | {mean:.4f} (x{mean / own:.2f}) |"
        )
    return "\n".join(lines)


def teacher_forced_losses(module, run: Path, config: dict) -> dict:
    """The network's teacher-forced next-pose loss on the run's validation windows with their own music, with
    each window's music swapped for another window's (rolled by one in the batch), and with every music frame
    set to the training mean (the model's normalised zero): how much the prediction leans on the music."""
    data = dict(config["data"]["init_args"])
    data.update(root=str(run.parent / "data"), batch_size=8, num_workers=0)
    dm = StreamDanceDataModule(**data)
    dm.setup("validate")
    losses = {"own music": [], "another window's music": [], "mean music": []}
    with torch.no_grad():
        for batch in dm.val_dataloader():
            motion, music = batch["motion"], batch["music"]
            prev = teacher_forcing_inputs(motion)
            flat = module.model.music_mean.expand_as(music)
            for key, condition in (("own music", music), ("another window's music", music.roll(1, 0)),
                                   ("mean music", flat)):  # fmt: skip
                losses[key].append(float(F.mse_loss(module.model(prev, condition), motion)))
    return {key: float(np.mean(values)) for key, values in losses.items()}


def _lagged(scores: dict) -> str:
    lag = scores["best_lag_frames"]
    return "" if lag is None else f"{scores['lagged_margins'][lag]:+.3f} ({lag} frames, {lag / FPS:.2f} s)"


def _ratio(value: float | None) -> str:
    return "n/a (under 15 s)" if value is None else f"{value:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", nargs="+", type=Path, default=[], help="stream_dance_demo log folders")
    parser.add_argument("--songs", nargs="*", type=Path, default=None, help="default: ../shared/data/music")
    parser.add_argument("--seconds", type=float, default=30.0, help="dance to at most this much of each song")
    parser.add_argument("--json", action="store_true", help="write bench_conditioning.json beside")
    parser.add_argument("--table", action="store_true", help="print the README table of the saved JSON")
    args = parser.parse_args()
    if args.table:
        print(table(json.loads(Path(__file__).with_suffix(".json").read_text())))
        return
    songs = args.songs if args.songs is not None else sorted(SHARED_MUSIC.glob("*.opus"))
    torch.manual_seed(0)
    report = {
        "machine": machine_info(),
        "date": time.strftime("%Y-%m-%d"),
        "seconds": args.seconds,
        "runs": {},
    }
    for run in args.runs:
        module = load_module_from(StreamDanceModule, str(run / "checkpoints" / "last.ckpt")).eval()
        model = module.model
        held_out = sorted((run / "demo").glob("*_dance.wav"))[:1]
        truth = load_motion(next((run / "demo").glob("*_reference.npz"))).joints
        config = yaml.safe_load((run / "config.yaml").read_text())
        hparams = module.hparams
        results = {"seed": config.get("seed_everything"), "truth": {"tilt_deg": tilt_deg(truth)},
                   "teacher_forced_loss": teacher_forced_losses(module, run, config),
                   "filter_delay_frames": hparams.smoothing_stages * hparams.smoothing_decay
                   / (1 - hparams.smoothing_decay)}  # fmt: skip
        print(
            f"{run.name} (seed {results['seed']}) teacher-forced validation loss: "
            + ", ".join(f"{k} {v:.4f}" for k, v in results["teacher_forced_loss"].items()),
            flush=True,
        )
        for song in [*held_out, *songs]:
            audio, _ = librosa.load(song, sr=SR, mono=True, duration=args.seconds)
            beats = music_beats(audio)
            kind = "held-out synthetic" if song in held_out else "real"
            entry = {"kind": kind, "beats": len(beats), "music": score(dance(model, audio), beats),
                     "silence": score(dance(model, np.zeros_like(audio)), beats)}  # fmt: skip
            if song in held_out:
                entry["truth"] = score(truth[: len(audio) // HOP], beats)
            results[song.name] = entry
            m, s = entry["music"], entry["silence"]
            truth_margin = f", truth {entry['truth']['margin']:+.3f}" if "truth" in entry else ""
            print(f"{run.name} {song.name} ({kind}): margin {m['margin']:+.3f} (silence {s['margin']:+.3f}"
                  f"{truth_margin}), against late beats {_lagged(m)}, "
                  f"freeze ratio {_ratio(m['freeze_ratio'])}, tilt {m['tilt_deg']:.1f} deg "
                  f"(truth {results['truth']['tilt_deg']:.1f})", flush=True)  # fmt: skip
        report["runs"][str(run)] = results
    if args.json:
        write_report(__file__, report)


if __name__ == "__main__":
    main()
