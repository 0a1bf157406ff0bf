"""Why the QEAN demo dancer freezes on long songs: the causes issue 58 (item 4) names, each measured.

    python benchmarks/qean_freeze_cause.py --run runs/qean_demo/version_0 [--songs FILE...] [--json]
    python benchmarks/qean_freeze_cause.py --table      # the README table of the saved JSON
    python benchmarks/qean_freeze_cause.py --run RUN --json --out benchmarks/qean_freeze_chained.json

For a trained ``qean_demo.yaml`` run (its log folder: ``checkpoints/last.ckpt``, ``config.yaml`` and the
synthetic set under ``<run>/../data``) and each song (the held-out synthetic tracks, looped to ``--seconds``,
and the real recordings of ``../shared/data/music``; skipped with a message when absent), the whole song is
danced as ``sm predict`` dances it (:meth:`QEANModule.generate`: the seed's 60 frames, then one kept frame per
network call, :func:`~skeleton_mamba.tasks.qean.generate.generate_fast`) from the first held-out dance's seed,
and scored per 5 s block (the seed is the first second of block 0):

- ``amplitude``: root-relative joint positions' standard deviation over the block, mean over joints (m);
- ``speed``: mean joint speed (m/s, world positions);
- ``freeze_ratio``: the smallest block from 10 s on over the largest (of amplitude, and of speed);
- ``margin``: BeatAlign (Bailando's) over its chance
  (:func:`~skeleton_mamba.tasks.motion.metrics.beat_align.beat_align_over_chance`) on the song's beats (the
  music features' beat channel: librosa's tracker at the motion's 60 fps).

Then the probes, each against that plain dance:

- rollout length: the dance started at 15 s of the song (the same seed): is it lively for its first seconds
  (the freeze follows the steps since the seed) or frozen at once (it follows the song's time)? And, over the
  plain dance, the speed of every 20-frame span after 1, 2, 5, 10, 20, ... steps, and the network's whole
  predicted 20-frame window there against the 20 frames it was given last (``window_gain``: below 1, every
  call asks for less motion than it saw, and the dance decays geometrically);
- the seed's share: the same song from another seed (a training dance's first 60 frames) and from a still
  seed (the first frame held for 60 frames): their amplitude and their distance to the plain dance per block
  (mean root-relative joint distance, m);
- the music: the same seed with the music swapped (another song), shifted by 2.5 s, and zero features (what
  the network gets past a song's end): distance to the plain dance per block, against the plain dance's own
  amplitude (a network that ignores the music late in the song gives distances near 0 there);
- the training distribution: on the held-out dances' windows, the 20-frame loss with the true seed, with the
  seed training builds (its last 20 frames the network's one-call prediction), and with a seed of 60 frames
  generated one per call (generation from 1 s on), with the speed of each kind of seed; and the song danced
  keeping all 20 predicted frames per call (the training rollout's way) instead of one.
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

from skeleton_mamba.tasks.motion.formats.fact_features import FPS, features_to_joints  # noqa: E402
from skeleton_mamba.tasks.motion.metrics.beat_align import beat_align_over_chance  # noqa: E402
from skeleton_mamba.tasks.motion.music.features import beat_frames  # noqa: E402
from skeleton_mamba.tasks.qean.data import AISTPPDanceDataModule  # noqa: E402
from skeleton_mamba.tasks.qean.generate import generate_fast, pad_music  # noqa: E402
from skeleton_mamba.tasks.qean.module import QEANModule  # noqa: E402
from skeleton_mamba.tasks.training.pretrained import load_module_from  # noqa: E402

SHARED_MUSIC = Path(__file__).resolve().parents[2] / "shared" / "data" / "music"
BLOCK_SECONDS = 5.0
PELVIS = 0
STEP_COUNTS = (1, 2, 5, 10, 20, 40, 80)  # spans of 20 frames after the seed, for the rollout-length probe
SHIFT_S = 2.5


# ----- scores -----
def joints_of(features: torch.Tensor) -> np.ndarray:
    """(T, 219) FACT motion vectors -> (T, 24, 3) joint positions (m)."""
    return features_to_joints(features.double()).numpy()


def block_amplitude(joints: np.ndarray, size: int) -> list[float]:
    """Per block of ``size`` frames: std over its frames of root-relative joints, mean over joints (m)."""
    relative = joints - joints[:, PELVIS : PELVIS + 1]
    return [float(relative[i : i + size].std(axis=0).mean()) for i in range(0, len(joints) - size + 1, size)]


def block_speed(joints: np.ndarray, size: int, fps: float = FPS) -> list[float]:
    """Per block of ``size`` frames: mean joint speed (m/s) of the world positions."""
    speed = np.linalg.norm(np.diff(joints, axis=0), axis=-1).mean(axis=-1) * fps  # (T - 1,)
    starts = range(0, len(joints) - size + 1, size)
    return [float(speed[i : i + size].mean()) for i in starts]  # the last block: size - 1 steps


def block_distance(a: np.ndarray, b: np.ndarray, size: int) -> list[float]:
    """Per block: mean distance (m) between the root-relative joints of two dances of the same length."""
    ra, rb = a - a[:, PELVIS : PELVIS + 1], b - b[:, PELVIS : PELVIS + 1]
    d = np.linalg.norm(ra - rb, axis=-1).mean(axis=-1)
    return [float(d[i : i + size].mean()) for i in range(0, len(d) - size + 1, size)]


def freeze_ratio(values: list[float], from_block: int = 2) -> float | None:
    """The smallest block from ``from_block`` on (10 s for 5 s blocks) over the largest; None if too short."""
    late = values[from_block:]
    if not late or max(values) <= 0:
        return None if not late else 0.0
    return min(late) / max(values)


def score(joints: np.ndarray, beats: np.ndarray, fps: float = FPS) -> dict:
    """Blocks of amplitude and speed, their freeze ratios and the BeatAlign margin over chance."""
    size = int(BLOCK_SECONDS * fps)
    amplitude, speed = block_amplitude(joints, size), block_speed(joints, size, fps)
    align, chance = beat_align_over_chance(joints, beats, "bailando", fps)
    return {
        "amplitude": amplitude, "speed": speed, "freeze_ratio": freeze_ratio(amplitude),
        "speed_ratio": freeze_ratio(speed), "beat_align": align, "chance": chance, "margin": align - chance,
    }  # fmt: skip


def window_speed(features: torch.Tensor) -> torch.Tensor:
    """(B, T, 219) -> (B,) mean joint speed (m/s) over the frames."""
    j = features_to_joints(features.double())
    return (j.diff(dim=1).norm(dim=-1).mean(dim=(1, 2)) * FPS).float()


# ----- generation -----
def dance(module: QEANModule, seed: torch.Tensor, music: torch.Tensor, frames: int) -> torch.Tensor:
    """``[seed | generated]`` (B, 60 + frames, 219) as ``sm predict`` dances (one kept frame per call)."""
    with torch.no_grad():
        return module.generate(seed, music, frames=frames)


@torch.no_grad()
def dance_in_chunks(module: QEANModule, seed: torch.Tensor, music: torch.Tensor, frames: int) -> torch.Tensor:
    """As :func:`dance`, but every call's whole predicted window is kept (training's rollout of 20 frames)."""
    model, c = module.model, module.model.config
    music = pad_music(music, frames + c.predict_frames, c.music_frames)
    motion = seed[:, -c.seed_frames :]
    i = 0
    while i < frames:
        window = model(motion[:, -c.seed_frames :], music[:, i : i + c.music_frames])
        motion = torch.cat([motion, window], dim=1)
        i += window.shape[1]
    return motion[:, : c.seed_frames + frames]


@torch.no_grad()
def window_gain(module: QEANModule, full: torch.Tensor, music: torch.Tensor) -> dict:
    """Every ``predict_frames`` frames of a dance ``full`` (B, S + G, 219): the network's whole predicted
    window from the dance's last S frames there, its speed against that of the last ``predict_frames``
    frames it was given. Keys: ``step`` (frames after the seed), ``given``, ``predicted``, ``gain``."""
    model, c = module.model, module.model.config
    s, p = c.seed_frames, c.predict_frames
    music = pad_music(music, full.shape[1], c.music_frames)
    steps, given, predicted = [], [], []
    for i in range(0, full.shape[1] - s - p + 1, p):
        context = full[:, i : i + s]
        window = model(context, music[:, i : i + c.music_frames])
        steps.append(i)
        given.append(float(window_speed(context[:, -p:]).mean()))
        predicted.append(float(window_speed(torch.cat([context[:, -1:], window], dim=1)).mean()))
    gain = [b / a if a > 0 else float("nan") for a, b in zip(given, predicted, strict=True)]
    return {"step": steps, "given": given, "predicted": predicted, "gain": gain}


def spans_after_steps(generated: torch.Tensor, span: int, counts=STEP_COUNTS) -> dict[int, float]:
    """Mean joint speed (m/s) of the ``span`` frames ending after ``k`` steps of ``span`` frames, per k."""
    out = {}
    for k in counts:
        if k * span <= generated.shape[1]:
            out[k] = float(window_speed(generated[:, (k - 1) * span : k * span]).mean())
    return out


@torch.no_grad()
def seed_kinds_loss(module: QEANModule, motion: torch.Tensor, music: torch.Tensor, starts: list[int]) -> dict:
    """On windows of one true dance ``motion`` (T, 219) with its ``music`` (T', 35) starting at ``starts``
    (each >= S): the 20-frame loss and the seed's speed with the true seed, training's seed (its last
    ``predict_frames`` frames the network's prediction of one call from ``predict_frames`` frames earlier),
    and a seed generated one frame per call for its whole S frames from the true seed S frames earlier."""
    model, c = module.model, module.model.config
    s, p, m = c.seed_frames, c.predict_frames, c.music_frames
    mus = pad_music(music[None], motion.shape[0] + s, m)[0]
    true, trained, generated, targets, musics = [], [], [], [], []
    for t in starts:
        seed = motion[t - s : t]
        true.append(seed)
        own = model(motion[None, t - s - p : t - p], mus[None, t - s - p : t - s - p + m])[0]
        trained.append(torch.cat([seed[: s - p], own], dim=0))
        rolled = generate_fast(model, motion[None, t - 2 * s : t - s], mus[None, t - 2 * s :], s)[0]
        generated.append(rolled)
        targets.append(motion[t : t + p])
        musics.append(mus[t - s : t - s + m])
    target, music_windows = torch.stack(targets), torch.stack(musics)
    out = {}
    for name, seeds in (("true seed", true), ("training's seed (20 own frames of one call)", trained),
                        ("generated seed (60 own frames, one per call)", generated)):  # fmt: skip
        seeds = torch.stack(seeds)
        pred = model(seeds, music_windows)
        out[name] = {
            "loss": float(F.mse_loss(pred, target)),
            "seed_speed": float(window_speed(seeds[:, -p:]).mean()),
            "predicted_speed": float(window_speed(torch.cat([seeds[:, -1:], pred], dim=1)).mean()),
        }
    return out


# ----- the run -----
def songs_of(run: Path, dm: AISTPPDanceDataModule, songs: list[Path], seconds: float) -> dict:
    """name -> (kind, music features (T, 35)) for the held-out synthetic tracks (looped) and ``songs``."""
    out = {}
    frames = int(seconds * FPS)
    for name in dm.split_names("val"):
        music = dm.sequence(name)[1]
        loops = -(-frames // len(music))
        out[f"{name} (looped)"] = ("held-out synthetic, looped", music.repeat(loops, 1)[:frames])
    for song in songs:
        if not song.is_file():
            print(f"skipped {song}: not found", flush=True)
            continue
        out[song.name] = ("real", dm.music_features(song)[:frames])
    return out


def measure_song(module, music: torch.Tensor, other: torch.Tensor, seeds: dict[str, torch.Tensor]) -> dict:
    """The plain dance of one song and every probe against it."""
    c = module.model.config
    frames = len(music) - c.seed_frames
    size = int(BLOCK_SECONDS * FPS)
    beats = beat_frames(music.numpy())
    seed = seeds["held-out"]
    shift = int(SHIFT_S * FPS)
    other = other.repeat(-(-len(music) // len(other)), 1)[: len(music)]
    variants = {  # name -> (seed, music), danced together in one batch
        "plain": (seed, music),
        "another seed": (seeds["another"], music),
        "still seed": (seed[:1].expand(c.seed_frames, -1), music),
        "swapped music": (seed, other),
        "shifted music": (seed, torch.cat([music[shift:], music[:shift]])),
        "zero music": (seed, torch.zeros_like(music)),
    }
    batch_seed = torch.stack([v[0] for v in variants.values()])
    batch_music = torch.stack([v[1] for v in variants.values()])
    full = dance(module, batch_seed, batch_music, frames)
    joints = {name: joints_of(full[i]) for i, name in enumerate(variants)}
    result = {"frames": frames, "beats": len(beats)}
    plain = joints["plain"]
    result["plain"] = score(plain, beats)
    result["variants"] = {
        name: {"amplitude": block_amplitude(j, size), "speed": block_speed(j, size),
               "distance_to_plain": block_distance(j, plain, size)}
        for name, j in joints.items() if name != "plain"
    }  # fmt: skip
    # rollout length: the same seed placed at 15 s of the song
    start = int(15 * FPS)
    if len(music) - start > c.seed_frames + size:
        late = dance(module, seed[None], music[None, start:], len(music) - start - c.seed_frames)[0]
        lj = joints_of(late)
        result["started_at_15s"] = {"amplitude": block_amplitude(lj, size), "speed": block_speed(lj, size)}
    generated = full[:1, c.seed_frames :]
    result["speed_after_steps"] = spans_after_steps(generated, c.predict_frames)
    result["window_gain"] = window_gain(module, full[:1], music[None])
    chunked = dance_in_chunks(module, seed[None], music[None], frames)[0]
    cj = joints_of(chunked)
    result["kept_20_per_call"] = {"amplitude": block_amplitude(cj, size), "speed": block_speed(cj, size),
                                  "freeze_ratio": freeze_ratio(block_amplitude(cj, size))}  # fmt: skip
    return result


def measure(run: Path, songs: list[Path], seconds: float) -> dict:
    ckpt = run / "checkpoints" / "last.ckpt"
    if not ckpt.is_file():
        raise FileNotFoundError(f"{ckpt}: no checkpoint (train with `sm fit --recipe qean_demo.yaml`)")
    config_file = run / "config.yaml"
    if not config_file.is_file():
        raise FileNotFoundError(f"{config_file}: the run's config is missing")
    module = load_module_from(QEANModule, str(ckpt)).eval()
    config = yaml.safe_load(config_file.read_text())
    data = dict(config["data"]["init_args"])
    data.update(root=str(run.parent / "data"), num_workers=0)
    dm = AISTPPDanceDataModule(**data)
    if not (dm.root / "motions").is_dir():
        raise FileNotFoundError(f"{dm.root / 'motions'}: the run's synthetic set is missing")
    c = module.model.config
    held_out, train = dm.split_names("val"), dm.split_names("train")
    seeds = {"held-out": dm.sequence(held_out[0])[0][: c.seed_frames],
             "another": dm.sequence(train[0])[0][: c.seed_frames]}  # fmt: skip
    truth = joints_of(dm.sequence(held_out[0])[0])
    size = int(BLOCK_SECONDS * FPS)
    report = {
        "run": str(run), "seed_frames": c.seed_frames, "predict_frames": c.predict_frames,
        "rollout_frames": data.get("rollout_frames"),
        "rollout_probability": module.hparams.rollout_probability,
        "smoothing": [c.smoothing_stages, c.smoothing_decay],
        "truth": {"amplitude": block_amplitude(truth, size), "speed": block_speed(truth, size)},
    }  # fmt: skip
    demo = run / "demo" / "demo.json"  # what the run's demo printed on the held-out dances, when it ran
    if demo.is_file():
        printed = json.loads(demo.read_text())
        report["demo"] = {"dance": printed["scores"]["dance"], "checks": printed["checks"]}
    # training distribution, on every held-out dance
    losses = []
    for name in held_out:
        motion, music = dm.sequence(name)
        starts = list(range(2 * c.seed_frames, len(motion) - c.predict_frames + 1, 30))
        losses.append(seed_kinds_loss(module, motion, music, starts))
    report["seed_kinds"] = {k: {m: float(np.mean([x[k][m] for x in losses])) for m in losses[0][k]}
                            for k in losses[0]}  # fmt: skip
    t = report["truth"]
    print(f"held-out truth: amplitude {_row(t['amplitude'])} | speed {_row(t['speed'])}", flush=True)
    print("training distribution (held-out windows):", flush=True)
    for k, v in report["seed_kinds"].items():
        print(f"  {k}: loss {v['loss']:.4f}, seed speed {v['seed_speed']:.3f} m/s, "
              f"predicted speed {v['predicted_speed']:.3f} m/s", flush=True)  # fmt: skip
    tracks = songs_of(run, dm, songs, seconds)
    names = list(tracks)
    report["songs"] = {}
    for i, name in enumerate(names):
        kind, music = tracks[name]
        other = tracks[names[(i + 1) % len(names)]][1]
        started = time.perf_counter()
        result = measure_song(module, music, other, seeds)
        result["kind"] = kind
        result["seconds_to_measure"] = round(time.perf_counter() - started, 1)
        report["songs"][name] = result
        print(song_table(name, result), flush=True)
    print("finding (measured):", finding(report), flush=True)
    return report


# ----- tables -----
def _row(values: list[float], fmt: str = "{:.3f}") -> str:
    return " ".join(fmt.format(v) for v in values)


def song_table(name: str, r: dict) -> str:
    """One song's printed table."""
    p = r["plain"]
    fr = "n/a" if p["freeze_ratio"] is None else f"{p['freeze_ratio']:.2f}"
    sr = "n/a" if p["speed_ratio"] is None else f"{p['speed_ratio']:.2f}"
    lines = [
        f"== {name} ({r['kind']}, {r['frames']} frames after the seed, {r['beats']} beats)",
        f"  plain:       amplitude/5 s [m] {_row(p['amplitude'])} | speed [m/s] {_row(p['speed'])}",
        f"               freeze ratio {fr} (speed {sr}), BeatAlign margin {p['margin']:+.3f}",
    ]
    for v, x in r["variants"].items():
        lines.append(
            f"  {v:<13} amplitude {_row(x['amplitude'])} | distance to plain {_row(x['distance_to_plain'])}"
        )
    if "started_at_15s" in r:
        s = r["started_at_15s"]
        lines.append(f"  seed at 15 s: amplitude {_row(s['amplitude'])} | speed {_row(s['speed'])}")
    k = r["kept_20_per_call"]
    lines.append(f"  20 per call: amplitude {_row(k['amplitude'])} | speed {_row(k['speed'])}")
    steps = r["speed_after_steps"]
    lines.append("  speed after k steps of 20: " + ", ".join(f"{k}: {v:.3f}" for k, v in steps.items()))
    g = r["window_gain"]
    pick = [i for i in range(len(g["step"])) if g["step"][i] // 20 + 1 in STEP_COUNTS]
    lines.append(
        "  predicted window / given speed: "
        + ", ".join(f"{g['step'][i] // 20 + 1}: {g['predicted'][i]:.3f}/{g['given'][i]:.3f}" for i in pick)
    )
    return "\n".join(lines)


def _late(values: list[float], from_block: int = 2) -> float:
    """Mean of the blocks from 10 s on (NaN when the dance is shorter)."""
    return float(np.mean(values[from_block:])) if len(values) > from_block else float("nan")


def finding(report: dict) -> str:
    """The measured facts behind the finding, one paragraph, every figure from ``report``."""
    songs = [r for r in report["songs"].values() if len(r["plain"]["amplitude"]) > 2]
    if not songs:
        return "no song of 15 s or more was danced"
    first = np.mean([r["plain"]["speed"][0] for r in songs])
    late = np.mean([_late(r["plain"]["speed"]) for r in songs])
    ratio = np.mean([r["plain"]["freeze_ratio"] for r in songs])
    margin = np.mean([r["plain"]["margin"] for r in songs])
    fresh = [r for r in songs if "started_at_15s" in r and len(r["plain"]["speed"]) > 3]
    fresh_speed = np.mean([r["started_at_15s"]["speed"][0] for r in fresh]) if fresh else float("nan")
    same_time = np.mean([r["plain"]["speed"][3] for r in fresh]) if fresh else float("nan")
    steps = {k: np.mean([r["speed_after_steps"][k] for r in songs if k in r["speed_after_steps"]])
             for k in songs[0]["speed_after_steps"]}  # fmt: skip
    gains = []
    for r in songs:
        g = r["window_gain"]
        gains += [
            x for i, x in zip(g["step"], g["gain"], strict=True) if i >= 10 * FPS - report["seed_frames"]
        ]
    kinds = report["seed_kinds"]
    true = next(iter(kinds.values()))
    true_gain = true["predicted_speed"] / true["seed_speed"]

    def dist(name: str) -> float:
        return float(np.mean([_late(r["variants"][name]["distance_to_plain"]) for r in songs]))

    def dist_last(name: str) -> str:
        return " ".join(f"{r['variants'][name]['distance_to_plain'][-1]:.3f}" for r in songs)

    amp = np.mean([_late(r["plain"]["amplitude"]) for r in songs])
    loss = " / ".join(f"{v['loss']:.4f}" for v in kinds.values())
    seed_speed = " / ".join(f"{v['seed_speed']:.3f}" for v in kinds.values())
    pred_speed = " / ".join(f"{v['predicted_speed']:.3f}" for v in kinds.values())
    chunk = np.mean([_late(r["kept_20_per_call"]["speed"]) for r in songs])
    chunk_ratio = np.mean([r["kept_20_per_call"]["freeze_ratio"] for r in songs])
    return (
        f"Over {len(songs)} songs of 15 s or more: joint speed {first:.3f} m/s in the first 5 s, {late:.3f} "
        f"from 10 s on; freeze ratio (amplitude) {ratio:.2f}; BeatAlign margin {margin:+.3f}. "
        f"Rollout length: the speed of the 20 frames after k steps of 20 frames is "
        + ", ".join(f"{v:.3f} (k={k})" for k, v in steps.items())
        + f"; the same seed placed at 15 s dances its first 5 s at {fresh_speed:.3f} m/s where the plain "
        f"dance, at the same time of the song, moves at {same_time:.3f}. Each call's whole predicted window "
        f"against the 20 frames it was given: speed gain {np.mean(gains):.2f} (mean from 10 s on) on its own "
        f"frames, {true_gain:.2f} on the held-out dances' true seeds. The seed's share: from 10 s on, "
        f"another seed's dance is {dist('another seed'):.3f} m (mean joint distance) from the plain one, "
        f"a still seed's "
        f"{dist('still seed'):.3f} m. The music: swapped {dist('swapped music'):.3f} m, shifted by "
        f"{SHIFT_S} s {dist('shifted music'):.3f} m, zero features {dist('zero music'):.3f} m (the plain "
        f"dance's own amplitude there: {amp:.3f} m); in the last 5 s block, song by song: another seed "
        f"{dist_last('another seed')}, swapped music {dist_last('swapped music')}, shifted "
        f"{dist_last('shifted music')} m. Training distribution, held-out windows (true seed / "
        f"training's seed, 20 own frames of one call / 60 own frames, one per call): 20-frame loss {loss}, "
        f"seed speed {seed_speed} m/s, predicted speed {pred_speed} m/s. Keeping all 20 frames of each call "
        f"(as the training rollout does): speed from 10 s on {chunk:.3f} m/s, freeze ratio {chunk_ratio:.2f}."
    )


def table(report: dict) -> str:
    """The markdown table of ``benchmarks/README.md`` from a report (``--table`` prints it)."""
    lines = []
    if "demo" in report:  # the demo's own dynamics on the held-out dances (against the ground truth's)
        d, checks = report["demo"]["dance"], report["demo"]["checks"]
        failed = [k for k, ok in checks.items() if not ok]
        lines += [
            f"Training rollouts of {report['rollout_frames']} frames; the demo printed amplitude ratio "
            f"{d['amplitude_ratio']:.2f}, jitter ratio {d['jitter_ratio']:.2f}, energy above 6 Hz "
            f"{d['high_frequency_ratio']:.1f}x the truth's ("
            + ("every target reached" if not failed else "NOT reached: " + "; ".join(failed))
            + ").",
            "",
        ]
    lines += [
        "| song | amplitude per 5 s (m) | speed per 5 s (m/s) | freeze ratio | margin | seed at 15 s: "
        "amplitude | 20 frames kept per call: amplitude | distance to plain in the last 5 s block (m): "
        "another seed / still seed / swapped / shifted / zero music |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, r in report["songs"].items():
        p = r["plain"]
        fr = "n/a" if p["freeze_ratio"] is None else f"{p['freeze_ratio']:.2f}"
        last = " / ".join(
            f"{r['variants'][v]['distance_to_plain'][-1]:.3f}"
            for v in ("another seed", "still seed", "swapped music", "shifted music", "zero music")
        )
        s15 = _row(r["started_at_15s"]["amplitude"]) if "started_at_15s" in r else "n/a"
        lines.append(
            f"| {name} | {_row(p['amplitude'])} | {_row(p['speed'])} | {fr} | {p['margin']:+.3f} | {s15} | "
            f"{_row(r['kept_20_per_call']['amplitude'])} | {last} |"
        )
    lines += [
        "",
        "| seed of the held-out windows | 20-frame loss | seed speed (m/s) | predicted speed (m/s) |",
        "|---|---|---|---|",
    ]
    for k, v in report["seed_kinds"].items():
        lines.append(f"| {k} | {v['loss']:.4f} | {v['seed_speed']:.3f} | {v['predicted_speed']:.3f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", type=Path, help="a qean_demo log folder (runs/qean_demo/version_N)")
    parser.add_argument("--songs", nargs="*", type=Path, default=None, help="default: ../shared/data/music")
    parser.add_argument("--seconds", type=float, default=33.0, help="dance to at most this much of each song")
    parser.add_argument("--json", action="store_true", help="write qean_freeze_cause.json beside (or --out)")
    parser.add_argument("--table", action="store_true", help="print the README table of the saved JSON")
    parser.add_argument("--out", type=Path, default=None, help="the JSON --json writes and --table reads")
    args = parser.parse_args()
    saved = args.out or Path(__file__).with_suffix(".json")
    if args.table:
        report = json.loads(saved.read_text())
        print(table(report) + "\n\n" + finding(report))
        return
    if args.run is None:
        parser.error("--run is required (or --table)")
    if args.songs is not None:
        songs = args.songs
    elif SHARED_MUSIC.is_dir():
        songs = sorted(SHARED_MUSIC.glob("*.opus"))
    else:
        print(f"no real recordings: {SHARED_MUSIC} is not a folder (held-out synthetic tracks only)")
        songs = []
    torch.manual_seed(0)
    report = {
        "machine": machine_info(),
        "threads": torch.get_num_threads(),
        "date": time.strftime("%Y-%m-%d"),
    }
    report.update(measure(args.run, songs, args.seconds))
    if args.json:
        write_report(__file__, report, args.out)


if __name__ == "__main__":
    main()
