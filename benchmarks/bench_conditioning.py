"""Does the live dancer follow the music? Its beat against chance on songs it never heard, and in silence.

    python benchmarks/bench_conditioning.py --runs RUN... [--songs FILE...] [--seconds 30] [--json] [--table]

For each trained ``stream_dance_demo.yaml`` run (its log folder: ``checkpoints/last.ckpt``, ``config.yaml``,
the data under ``../data``) and each song outside the recorded-music demo set's training tracks (default: its
two test songs and its five unheard songs, the three of the shared sample music among them, all from the
``immich-memories-music`` package: :mod:`~skeleton_mamba.tasks.motion.synthetic.recorded_music_set`), the
dancer dances as ``sm stream`` does (:class:`~skeleton_mamba.tasks.stream.live.LiveDancer`, frame by frame on
its own poses), then again to silence of the same length (what the network does from its own previous poses
alone). The song's ground truth is the dance the set's builder choreographs to it (its tracked beats and
sections). Each dance is scored on the song's beats (librosa's tracker at 30 fps):

- ``margin``: [Bailando]'s BeatAlign minus its chance, the same dance scored against the beat grid shifted by
  1/10 ... 9/10 of a beat (:func:`~skeleton_mamba.tasks.motion.metrics.beat_align.beat_align_over_chance`);
  0 means no relation to the beat. The dance to silence, scored on the song's beats, is the margin a dance
  that cannot hear the song gets;
- ``blocks``: pose amplitude (root-relative joint positions' standard deviation, mean over joints, m) per 5 s
  block, and ``freeze_ratio``, the smallest block from 10 s on over the largest (freezing: < 0.4);
- ``tilt_deg``: mean angle of the torso (pelvis to neck) from vertical, beside the truth's;
- ``lagged_margins``: the margin against the beats delayed by 0, 1, ... frames up to a beat period, and its
  best lag: a dance on the beat but late (the output's causal low-pass delays it by ``filter_delay_frames``,
  ``stages d / (1 - d)``) peaks there;
- per run, ``teacher_forced_loss``: the training loss on the validation windows with their own music,
  another window's, and the training mean (how much the next pose leans on the music).

The targets (issue 58, item 3), per seed on the songs outside its training set: mean margin >= 0.10, no song
below chance (margin < 0), no 5 s block from 10 s on below 0.4 of the dance's largest, and every song's mean
torso tilt within 1.5 times its truth's. Each song and seed is printed with pass / fail (``targets``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, write_report  # noqa: E402

from skeleton_mamba.tasks.motion.formats.fact_features import features_to_joints, motion_to_features  # noqa: E402
from skeleton_mamba.tasks.motion.metrics.beat_align import beat_align_over_chance  # noqa: E402
from skeleton_mamba.tasks.motion.music.features import load_audio  # noqa: E402
from skeleton_mamba.tasks.motion.synthetic import recorded_music_set as recorded  # noqa: E402
from skeleton_mamba.tasks.stream.data import StreamDanceDataModule  # noqa: E402
from skeleton_mamba.tasks.stream.features import FPS, HOP, SR  # noqa: E402
from skeleton_mamba.tasks.stream.live import LiveDancer  # noqa: E402
from skeleton_mamba.tasks.stream.model import teacher_forcing_inputs, tokens_to_features  # noqa: E402
from skeleton_mamba.tasks.stream.module import StreamDanceModule  # noqa: E402
from skeleton_mamba.tasks.training.pretrained import load_module_from  # noqa: E402

BLOCK_SECONDS = 5.0
MEAN_MARGIN, FREEZE, TILT = 0.10, 0.4, 1.5  # the targets (module docstring)
PELVIS, NECK = 0, 12  # SMPL-24


def dance(model, audio: np.ndarray) -> np.ndarray:
    """The live dancer's (T, 24, 3) joints (m) for mono audio at :data:`SR`, as ``sm stream`` dances."""
    dancer = LiveDancer(model, SR)
    with torch.no_grad():
        dancer.push(audio.astype(np.float32), last=True)
        return features_to_joints(tokens_to_features(dancer.tokens().double())).numpy()


def truth(audio: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The song's tracked beats (30 fps frames) and the (T, 24, 3) joints of the dance that the recorded-music
    set's builder choreographs to it."""
    piece = recorded.choreograph(audio, len(audio) // HOP)
    joints = features_to_joints(torch.as_tensor(motion_to_features(piece.motion, FPS))).numpy()
    return piece.beats, joints


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


def song_targets(music: dict, truth_tilt: float) -> dict[str, bool]:
    """A song's targets: not below chance, no freezing from 10 s on, torso tilt within 1.5x the truth's."""
    ratio = music["freeze_ratio"]
    return {
        "not below chance": music["margin"] >= 0.0,
        "no freezing": ratio is not None and ratio >= FREEZE,
        "tilt within 1.5x": music["tilt_deg"] <= TILT * truth_tilt,
    }


def seed_targets(results: dict) -> dict[str, bool]:
    """A seed's targets over its songs: mean margin >= 0.10, and every song's targets."""
    songs = [entry for entry in results.values() if isinstance(entry, dict) and "music" in entry]
    return {
        "mean margin >= 0.10": float(np.mean([e["music"]["margin"] for e in songs])) >= MEAN_MARGIN,
        **{key: all(e["targets"][key] for e in songs) for key in songs[0]["targets"]},
    }


def _verdict(targets: dict[str, bool]) -> str:
    failed = [key for key, ok in targets.items() if not ok]
    return "pass" if not failed else "fail: " + ", ".join(failed)


def _songs(results: dict) -> list[tuple[str, dict]]:
    return [(song, e) for song, e in results.items() if isinstance(e, dict) and "music" in e]


def table(report: dict) -> str:
    """The markdown tables of ``benchmarks/README.md`` from a report (``--table`` prints them): every song of
    the runs of the variant run on the most seeds (the recipe's), then every run's summary."""
    lines = [
        "| run | seed | song | margin to the song | margin in silence | truth's margin | "
        "best margin against late beats (lag) | smallest 5 s block from 10 s / largest | "
        "torso tilt (truth) | targets |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    runs = sorted(report["runs"].values(), key=lambda r: (r["variant"], r["seed"]))
    variants = [r["variant"] for r in runs]
    demo = max(variants, key=variants.count)  # the recipe's, run on every seed: its songs one by one
    for results in (r for r in runs if r["variant"] == demo):
        for song, entry in _songs(results):
            music, silence = entry["music"], entry["silence"]
            lines.append(
                f"| {results['variant']} | {results['seed']} | {song} ({entry['kind']}) | "
                f"{music['margin']:+.3f} | {silence['margin']:+.3f} | {entry['truth']['margin']:+.3f} | "
                f"{_lagged(music)} | {_ratio(music['freeze_ratio'])} | {music['tilt_deg']:.1f} deg "
                f"({entry['truth']['tilt_deg']:.1f}) | {_verdict(entry['targets'])} |"
            )
    lines += [
        "",
        "| run | seed | mean margin over the songs | songs below chance | output low-pass delay | "
        "teacher-forced loss: own music | another window's music | the music's training mean | targets |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for results in runs:
        songs = _songs(results)
        mean = float(np.mean([e["music"]["margin"] for _, e in songs]))
        below = sum(e["music"]["margin"] < 0 for _, e in songs)
        loss = results["teacher_forced_loss"]
        own, other, flat = loss["own music"], loss["another window's music"], loss["mean music"]
        lines.append(
            f"| {results['variant']} | {results['seed']} | {mean:+.3f} | {below} of {len(songs)} | "
            f"{results['filter_delay_frames']:.0f} frames | {own:.4f} | {other:.4f} (x{other / own:.2f}) | "
            f"{flat:.4f} (x{flat / own:.2f}) | {_verdict(results['targets'])} |"
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


def default_songs() -> list[tuple[Path, str]]:
    """The recorded-music set's test songs and unheard songs (the package's files), with their kind."""
    tracks = recorded.package_tracks()
    return [(tracks[name], "test song") for name in recorded.TEST_TRACKS] + [
        (tracks[name], "unheard") for name in recorded.UNHEARD_TRACKS
    ]


def variant(config: dict) -> str:
    """What a run was trained with: the demo set's music, the beat phase, the low-pass, the input noise, the
    history shift and the window length when not 90 frames (the defaults where the config predates them)."""
    data, model = config["data"]["init_args"], config["model"]["init_args"]
    parts = [
        data.get("synthetic_music", "drums"),
        "beat phase" if data.get("beat_phase") else "no beat phase",
        f"low-pass {model['smoothing_stages']}x{model['smoothing_decay']:g}",
        f"noise {model['input_noise']:g}",
    ]
    if model.get("history_shift"):
        parts.append(f"history shift {model['history_shift']}")
    if data["window_frames"] != 90:
        parts.append(f"windows of {data['window_frames']} frames")
    return ", ".join(parts)


def bench_run(run: Path, songs: list[tuple[Path, str]], seconds: float) -> dict:
    """Every score of one run (module docstring), printed as it goes."""
    module = load_module_from(StreamDanceModule, str(run / "checkpoints" / "last.ckpt")).eval()
    config = yaml.safe_load((run / "config.yaml").read_text())
    hparams = module.hparams
    results = {
        "seed": config.get("seed_everything"),
        "demo_set": config["data"]["init_args"].get("synthetic_music", "drums"),
        "variant": variant(config),
        "teacher_forced_loss": teacher_forced_losses(module, run, config),
        "filter_delay_frames": hparams.smoothing_stages
        * hparams.smoothing_decay
        / (1 - hparams.smoothing_decay),
    }
    print(
        f"{run} (seed {results['seed']}, {results['variant']}) teacher-forced validation loss: "
        + ", ".join(f"{k} {v:.4f}" for k, v in results["teacher_forced_loss"].items()),
        flush=True,
    )
    for song, kind in songs:
        audio = load_audio(song, SR, seconds)
        beats, truth_joints = truth(audio)
        entry = {
            "kind": kind,
            "beats": len(beats),
            "music": score(dance(module.model, audio), beats),
            "silence": score(dance(module.model, np.zeros_like(audio)), beats),
            "truth": score(truth_joints, beats),
        }
        entry["targets"] = song_targets(entry["music"], entry["truth"]["tilt_deg"])
        results[song.name] = entry
        m, s, t = entry["music"], entry["silence"], entry["truth"]
        print(
            f"  seed {results['seed']} {song.name} ({kind}): margin {m['margin']:+.3f} (silence "
            f"{s['margin']:+.3f}, truth {t['margin']:+.3f}), against late beats {_lagged(m)}, blocks "
            f"{' '.join(f'{b:.3f}' for b in m['blocks'])} (ratio {_ratio(m['freeze_ratio'])}), tilt "
            f"{m['tilt_deg']:.1f} deg (truth {t['tilt_deg']:.1f}): {_verdict(entry['targets'])}",
            flush=True,
        )
    results["targets"] = seed_targets(results)
    mean = float(np.mean([e["music"]["margin"] for _, e in _songs(results)]))
    print(f"  seed {results['seed']}: mean margin {mean:+.3f}: {_verdict(results['targets'])}", flush=True)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", nargs="+", type=Path, default=[], help="stream_dance_demo log folders")
    parser.add_argument(
        "--songs",
        nargs="*",
        type=Path,
        default=None,
        help="default: the recorded set's test and unheard songs",
    )
    parser.add_argument("--seconds", type=float, default=30.0, help="dance to at most this much of each song")
    parser.add_argument("--json", action="store_true", help="write bench_conditioning.json beside")
    parser.add_argument("--table", action="store_true", help="print the README table of the saved JSON")
    args = parser.parse_args()
    if args.table:
        print(table(json.loads(Path(__file__).with_suffix(".json").read_text())))
        return
    songs = default_songs() if args.songs is None else [(song, "given") for song in args.songs]
    torch.manual_seed(0)
    report = {
        "machine": machine_info(),
        "date": time.strftime("%Y-%m-%d"),
        "seconds": args.seconds,
        "runs": {},
    }
    for run in args.runs:
        report["runs"][str(run)] = bench_run(run, songs, args.seconds)
    if args.json:
        write_report(__file__, report)


if __name__ == "__main__":
    main()
