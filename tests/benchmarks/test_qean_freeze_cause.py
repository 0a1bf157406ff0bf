"""benchmarks/qean_freeze_cause.py's scores and probes on a tiny random QEAN (issue 58, item 4: the causes of
QEAN's freezing measured)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.tasks.motion.formats.fact_features import FPS as FACT_FPS
from skeleton_mamba.tasks.motion.music.features import BEAT, NUM_MUSIC_FEATURES
from skeleton_mamba.tasks.qean.model import QEANConfig
from skeleton_mamba.tasks.qean.module import QEANModule
from tests.helpers.repo import load_script

FPS = int(FACT_FPS)
bench = load_script("benchmarks/qean_freeze_cause.py")
REPO = Path(__file__).resolve().parents[2]
MARK, END = "<!-- qean_freeze_cause -->", "<!-- /qean_freeze_cause -->"
SIZES = dict(hidden=16, heads=2, motion_layers=1, audio_layers=1, cross_layers=1, mlp_dim=32, dropout=0.0)


def _module() -> QEANModule:
    torch.manual_seed(0)
    network = QEANConfig(
        **SIZES, seed_frames=12, music_frames=24, predict_frames=4, smoothing_stages=2, smoothing_decay=0.5
    )
    return QEANModule(network=network, render=False).eval()


def _swing(frames: int, amplitude: np.ndarray, stop_every: int = 30) -> np.ndarray:
    """(T, 24, 3): the neck 0.5 m above a fixed pelvis, the left hip swinging with ``amplitude`` (T,) and
    stopping every ``stop_every`` frames (at 0, 30, ...)."""
    t = np.arange(frames)
    joints = np.zeros((frames, 24, 3))
    joints[:, 12, 1] = 0.5
    joints[:, 1, 0] = amplitude * np.cos(2 * np.pi * t / (2 * stop_every))
    return joints


def test_a_still_motion_has_no_amplitude_speed_or_freeze_ratio():
    still = np.repeat(_swing(1, np.ones(1)), 20 * FPS, axis=0)
    scores = bench.score(still, np.arange(15, len(still), 30))
    assert len(scores["amplitude"]) == len(scores["speed"]) == 4  # 20 s in 5 s blocks
    assert max(scores["amplitude"]) == 0.0 and max(scores["speed"]) == 0.0
    assert scores["freeze_ratio"] == 0.0 and scores["speed_ratio"] == 0.0


def test_a_swing_that_halves_after_10_s_has_freeze_ratio_one_half_and_stops_on_the_beat():
    frames = 20 * FPS
    amplitude = np.where(np.arange(frames) < 10 * FPS, 1.0, 0.5)
    swing = _swing(frames, amplitude)
    on_beat = bench.score(swing, np.arange(0, frames, 30))  # beats on its stops
    off_beat = bench.score(swing, np.arange(15, frames, 30))  # beats half-way between its stops
    assert abs(on_beat["freeze_ratio"] - 0.5) < 0.01 and abs(on_beat["speed_ratio"] - 0.5) < 0.02
    assert on_beat["margin"] > 0.3 and off_beat["margin"] < 0
    # a 1 m cosine's std (1 / sqrt 2) on one of 24 x 3 joint coordinates, as bench_conditioning.py averages
    assert abs(on_beat["amplitude"][0] - 2**-0.5 / 72) < 1e-4


def test_block_distance_is_zero_to_itself_and_the_offset_between_two_poses():
    a = _swing(600, np.ones(600))
    b = a.copy()
    b[:, 1, 2] += 0.24  # one joint of 24 moved 0.24 m: a mean joint distance of 0.01 m
    assert bench.block_distance(a, a, 300) == [0.0, 0.0]
    assert np.allclose(bench.block_distance(a, b, 300), 0.01)


def test_the_probes_run_on_a_tiny_qean():
    module = _module()
    c = module.model.config
    frames = 11 * FPS  # 11 s of music: two 5 s blocks after the seed's first 12 frames
    music = torch.randn(frames, NUM_MUSIC_FEATURES)
    music[:, BEAT] = (torch.arange(frames) % 30 == 0).float()
    motion = torch.randn(frames, 219) * 0.1
    seeds = {"held-out": motion[: c.seed_frames], "another": motion[100 : 100 + c.seed_frames]}
    result = bench.measure_song(module, music, music.roll(50, 0), seeds)
    assert result["frames"] == frames - c.seed_frames and result["beats"] == 22
    assert len(result["plain"]["amplitude"]) == 2 and result["plain"]["freeze_ratio"] is None  # under 15 s
    assert set(result["variants"]) == {
        "another seed",
        "still seed",
        "swapped music",
        "shifted music",
        "zero music",
    }
    assert all(len(v["distance_to_plain"]) == 2 for v in result["variants"].values())
    assert min(result["variants"]["another seed"]["distance_to_plain"]) > 0  # a random net's seed matters
    gain = result["window_gain"]
    assert len(gain["step"]) == len(gain["gain"]) == (frames - c.seed_frames) // c.predict_frames
    assert gain["step"][:3] == [0, 4, 8]
    assert set(result["speed_after_steps"]) == {k for k in bench.STEP_COUNTS if k * 4 <= frames - 12}
    assert len(result["kept_20_per_call"]["amplitude"]) == 2
    # the plain dance is sm predict's: the seed, then one frame per call
    full = bench.dance(module, seeds["held-out"][None], music[None], 30)
    assert full.shape == (1, c.seed_frames + 30, 219) and torch.equal(
        full[0, : c.seed_frames], seeds["held-out"]
    )
    chunks = bench.dance_in_chunks(module, seeds["held-out"][None], music[None], 30)
    assert chunks.shape == full.shape
    first = module.model(seeds["held-out"][None], music[None, : c.music_frames])  # 4 frames of one call
    assert torch.allclose(chunks[0, c.seed_frames : c.seed_frames + 4], first[0], atol=1e-5)
    assert torch.allclose(full[0, c.seed_frames], first[0, 0], atol=1e-5)  # the first frame is kept alike


def test_seed_kinds_compare_the_true_trained_and_generated_seeds():
    module = _module()
    torch.manual_seed(1)
    motion, music = torch.randn(120, 219) * 0.1, torch.randn(120, NUM_MUSIC_FEATURES)
    out = bench.seed_kinds_loss(module, motion, music, [24, 50, 100])
    assert len(out) == 3
    true, trained, generated = out.values()
    assert true["seed_speed"] > 0 and all(np.isfinite(v["loss"]) for v in out.values())
    # training's seed keeps the true first S - P frames; the generated seed is the network's own throughout
    assert trained["seed_speed"] != true["seed_speed"] and generated["seed_speed"] != true["seed_speed"]


def test_the_readme_table_is_the_recorded_run():
    report = json.loads((REPO / "benchmarks" / "qean_freeze_cause.json").read_text())
    text = (REPO / "benchmarks" / "README.md").read_text(encoding="utf-8")
    block = text[text.index(MARK) + len(MARK) : text.index(END)].strip()
    assert block == bench.table(report) + "\n\n" + bench.finding(report), (
        "run `python benchmarks/qean_freeze_cause.py --table`"
    )
    assert report["songs"] and all(len(r["plain"]["amplitude"]) >= 6 for r in report["songs"].values())
