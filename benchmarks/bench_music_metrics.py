"""Benchmark: 35-d music feature extraction and the dance metrics.

Measures (wall time, median of ``--repeats``):

* librosa's first beat-tracking call in this process (numba JIT compile, or loading numba's on-disk cache
  when a previous run left one) and the first resampling call (``librosa.core.audio`` import);
* feature extraction for 30 s of music at 60 fps (FACT) and 30 fps (EDGE), after the warm-up, excluding
  decoding (decoding is reported separately);
* metrics for 40 generated sequences of 1200 frames (SMPL-24) against 40 real ones: kinetic and geometric
  features, FID_k, FID_g, Div_k, Div_g, BeatAlign (both variants), PFC, and MMV from precomputed video
  beats, plus Farneback optical flow on 150 frames of 224 x 224 for the MMV video term.

Usage::

    python benchmarks/bench_music_metrics.py [--json] [--repeats 3] [--audio FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, median_ms  # noqa: E402

DEFAULT_AUDIO = Path(__file__).resolve().parents[2] / "shared" / "data" / "music" / "happy_electronic_1.opus"


def _audio(path: Path | None, sr: int, seconds: float = 30.0) -> tuple[np.ndarray, str]:
    import librosa

    if path is not None and path.is_file():
        y, _ = librosa.load(path, sr=sr, duration=seconds)
        return y, str(path)
    t = np.arange(int(seconds * sr)) / sr  # fallback: 120 BPM clicks over a 220 Hz tone
    y = 0.1 * np.sin(2 * np.pi * 220 * t) + (np.mod(t, 0.5) < 0.02) * np.sin(2 * np.pi * 1000 * t)
    return y.astype(np.float32), "synthetic 120 BPM clicks"


def bench_music(audio: Path | None, repeats: int) -> dict:
    import librosa

    from skeleton_mamba.tasks.motion.music.features import compute_music_features

    out: dict = {}
    start = time.perf_counter()
    y60, source = _audio(audio, 60 * 512)
    out["first_load_and_resample_s"] = time.perf_counter() - start
    out["audio"] = source
    out["audio_seconds"] = len(y60) / (60 * 512)
    env = librosa.onset.onset_strength(y=y60, sr=60 * 512)
    start = time.perf_counter()
    librosa.beat.beat_track(onset_envelope=env, sr=60 * 512, hop_length=512, start_bpm=120.0, tightness=100)
    out["beat_track_first_call_s"] = time.perf_counter() - start
    out["beat_track_warm_ms"] = median_ms(
        lambda: librosa.beat.beat_track(onset_envelope=env, sr=60 * 512, hop_length=512, tightness=100),
        repeats=repeats,
    )
    out["decode_30s_ms"] = median_ms(lambda: _audio(audio, 60 * 512), repeats=repeats, warmup=0)
    out["features_60fps_30s_ms"] = median_ms(lambda: compute_music_features(y60, fps=60), repeats=repeats)
    y30, _ = _audio(audio, 30 * 512)
    out["features_30fps_30s_ms"] = median_ms(lambda: compute_music_features(y30, fps=30), repeats=repeats)
    return out


def bench_metrics(repeats: int, n: int = 40, frames: int = 1200) -> dict:
    from skeleton_mamba.tasks.motion.metrics import (
        MMV,
        PFC,
        BeatAlign,
        FrechetMotionDistance,
        MotionDiversity,
        flow_magnitudes,
        geometric_features,
        kinetic_features,
    )

    rng = np.random.default_rng(0)
    base = rng.normal(scale=0.3, size=(1, 1, 24, 3))
    real = torch.tensor(base + np.cumsum(rng.normal(scale=0.005, size=(n, frames, 24, 3)), axis=1))
    fake = torch.tensor(base + np.cumsum(rng.normal(scale=0.006, size=(n, frames, 24, 3)), axis=1))
    beats = [np.arange(15, frames, 30) for _ in range(n)]
    out: dict = {"sequences": n, "frames": frames}
    out["kinetic_features_ms"] = median_ms(lambda: kinetic_features(fake), repeats=repeats)
    out["geometric_features_ms"] = median_ms(lambda: geometric_features(fake), repeats=repeats)

    def fid_div(metric_cls, feature: str) -> float:
        metric = metric_cls(feature)
        metric.update(real, real=True)
        metric.update(fake, real=False)
        return metric.compute().item()

    for cls, name in ((FrechetMotionDistance, "fid"), (MotionDiversity, "div")):
        for feature, tag in (("kinetic", "k"), ("geometric", "g")):
            out[f"{name}_{tag}_ms"] = median_ms(lambda c=cls, f=feature: fid_div(c, f), repeats=repeats)

    def run(metric, *args, **kwargs):
        metric.update(*args, **kwargs)
        return metric.compute()

    for variant in ("fact", "bailando"):
        out[f"beat_align_{variant}_ms"] = median_ms(lambda v=variant: run(BeatAlign(v), fake, beats), repeats)
    out["pfc_ms"] = median_ms(lambda: run(PFC(fps=60), fake), repeats=repeats)
    out["mmv_from_video_beats_ms"] = median_ms(
        lambda: run(MMV(fps=60), fake, beats, video_beats=beats), repeats=repeats
    )
    video = rng.integers(0, 256, size=(150, 224, 224, 3), dtype=np.uint8)
    out["farneback_150x224x224_ms"] = median_ms(lambda: flow_magnitudes(video), repeats=max(1, repeats // 2))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--audio", type=Path, default=DEFAULT_AUDIO, help="audio file (>= 30 s)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    result = {
        "machine": machine_info(),
        "torch_threads": torch.get_num_threads(),
        "music": bench_music(args.audio, args.repeats),
        "metrics": bench_metrics(args.repeats),
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(result["machine"])
        for section in ("music", "metrics"):
            for key, value in result[section].items():
                text = f"{value:.1f}" if isinstance(value, float) else str(value)
                print(f"{section:8s} {key:32s} {text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
