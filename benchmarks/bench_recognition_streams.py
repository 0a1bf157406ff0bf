"""PYSKL's four streams on the synthetic recognition set, each alone and fused by ``sm ensemble``.

    python benchmarks/bench_recognition_streams.py [--json] [--epochs 8] [--input-norm both|on|off]

For each stream (``j``, ``b``, ``jm``, ``bm``) it runs ``sm fit`` and ``sm test`` of
``recognition_synthetic.yaml`` with ``--data.init_args.feats [STREAM]`` in a temporary folder, with and
without the recognizer's input normalisation (``--model.init_args.input_norm``), then ``sm ensemble`` of the
four (weights 1:1:1:1 and PYSKL's 2:2:1:1) and of joints + bones. Prints top-1 (%) per stream and fusion.
The synthetic set is three classes of procedural motion: a check that every stream learns and that the
fusion runs, not a benchmark of accuracy.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

STREAMS = ("j", "b", "jm", "bm")
FUSIONS = {"j+b+jm+bm 1:1:1:1": (STREAMS, None), "j+b+jm+bm 2:2:1:1": (STREAMS, ("2", "2", "1", "1")),
           "j+b 1:1": (("j", "b"), None)}  # fmt: skip


def _sm(args: list[str], cwd: Path) -> None:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-m", "skeleton_mamba.tasks", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, check=False)  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"sm {' '.join(args)} failed in {cwd}:\n{done.stderr[-2000:]}")


def run(work: Path, epochs: int, input_norm: bool) -> dict:
    """Fit and test every stream in ``work``; the top-1 of each and of each fusion."""
    recipe = ["--recipe", "recognition_synthetic.yaml"]
    logs = {}
    for stream in STREAMS:
        folder = work / stream
        folder.mkdir(parents=True)
        options = [
            f"--data.init_args.feats=[{stream}]",
            f"--model.init_args.input_norm={str(input_norm).lower()}",
            "--trainer.enable_progress_bar=false",
        ]
        _sm(["fit", *recipe, *options, f"--trainer.max_epochs={epochs}"], folder)
        ckpt = "runs/recognition_synthetic/version_0/checkpoints/last.ckpt"
        _sm(["test", *recipe, *options, "--ckpt_path", ckpt], folder)
        logs[stream] = folder / "runs/recognition_synthetic/version_1"
    out = {}
    for name, (streams, weights) in FUSIONS.items():
        target = work / f"ensemble_{len(out)}"
        _sm(["ensemble", *(str(logs[s]) for s in streams), *(["--weights", *weights] if weights else []),
             "--out", str(target)], work)  # fmt: skip
        report = json.loads((target / "ensemble.json").read_text())
        for record, stream in zip(report["runs"], streams, strict=True):
            out[stream] = round(100 * record["top1"], 2)
        out[name] = round(100 * report["ensemble"]["top1"], 2)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--epochs", type=int, default=8, help="training epochs per stream (the recipe's: 8)")
    p.add_argument("--input-norm", choices=("both", "on", "off"), default="both")
    args = p.parse_args(argv)
    settings = {"both": (False, True), "on": (True,), "off": (False,)}[args.input_norm]
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for norm in settings:
            key = f"input_norm={'on' if norm else 'off'}"
            results[key] = run(Path(tmp) / key, args.epochs, norm)
            if not args.json:
                print(key, json.dumps(results[key]))
    if args.json:
        print(
            json.dumps({"machine": machine_info(), "epochs": args.epochs, "top1_percent": results}, indent=2)
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
