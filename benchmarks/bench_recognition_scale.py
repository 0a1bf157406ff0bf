"""Recognition data at full size: setup time, memory per rank, the loader workers' growth, the batch wait.

    python benchmarks/bench_recognition_scale.py [--json] [--datasets ntu120 kinetics] [--scale 1.0]
        [--ranks 1 2] [--workers 2] [--modes store pickle] [--batches 0] [--work DIR]

Builds a synthetic annotation file of the data set's size in PYSKL's format (random keypoints in float16, as
PYSKL's own files store them; NTU120: 114,480 clips of 1-2 bodies x 40-200 frames x 25 joints x xyz;
Kinetics-skeleton: 260,232 clips of 2 bodies x 150-300 frames x 18 joints x (x, y) + scores), then:

- ``build``: the memory-mapped store made from it (:mod:`skeleton_mamba.tasks.recognition.keypoint_store`,
  once per machine), time and peak memory, in its own process;
- for each mode (``store``: the keypoints mapped from the store, today's default; ``pickle``: the file
  unpickled whole in every process, as before) and each rank count R: R processes started together, as DDP
  starts its ranks, each setting up the real :class:`RecognitionDataModule` for ``fit`` (timed), then reading
  its 1/R of the training split (a ``DistributedSampler``) through ``--workers`` loader workers, one epoch
  (``--batches`` > 0: that many batches), timing the wait for each batch.

Memory is read from ``/proc/PID/smaps_rollup``: ``private_dirty`` is memory a process alone has written (a
copy of the data it holds; for a forked loader worker, the pages copy-on-write gave it), ``pss`` its
proportional share of everything it maps (shared pages divided among their users; pages of a mapped file
that one process alone touches count as its own). Per rank: the private memory the data module added
(``data_private_mb``), its PSS after setup, its workers' private memory after their first batch and at the end
of the epoch (copy-on-write growth).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import pickle
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, write_report  # noqa: E402

from skeleton_mamba.tasks.recognition.keypoint_store import KeypointStore, store_folder  # noqa: E402

DATASETS = {
    # clips, classes, skeleton, joints, channels, bodies (p of 2), frames (low, high)
    "ntu120": dict(clips=114_480, classes=120, skeleton="ntu25", joints=25, channels=3, two_bodies=0.2,
                   frames=(40, 200), train_share=0.55),
    "kinetics": dict(clips=260_232, classes=400, skeleton="openpose18", joints=18, channels=2, two_bodies=1.0,
                     frames=(150, 300), train_share=0.924),
}  # fmt: skip


def _memory(pid: int | str = "self") -> dict[str, float]:
    """Rss, Pss, Anonymous and Private_Dirty of a process in MB (``/proc/PID/smaps_rollup``)."""
    out = {}
    with open(f"/proc/{pid}/smaps_rollup") as rollup:
        for line in rollup:
            key, _, rest = line.partition(":")
            if key in ("Rss", "Pss", "Anonymous", "Private_Dirty"):
                out[key.lower()] = int(rest.split()[0]) / 1024
    return out


PICKLE_COPIES = 3.2  # a rank unpickling a float16 file holds it and its float32 copy: 7.2 GB for 2.37 GB


def _available_mb() -> float:
    with open("/proc/meminfo") as info:
        return next(int(line.split()[1]) for line in info if line.startswith("MemAvailable:")) / 1024


def _children(pid: int) -> list[int]:
    with open(f"/proc/{pid}/task/{pid}/children") as handle:
        return [int(p) for p in handle.read().split()]


def describe(ann: Path, store_dir: Path) -> dict:
    """Clips, training clips, body-frames and file size of an annotation file, read from its built store."""
    store = KeypointStore(store_folder(ann, store_dir))
    return {"clips": len(store), "train_clips": len(store.splits["train"]),
            "body_frames": int(store.meta["rows"]), "file_mb": ann.stat().st_size / 2**20}  # fmt: skip


def make_dataset(name: str, scale: float, path: Path, seed: int = 0) -> None:
    """Write a PYSKL annotation pickle of ``name``'s size x ``scale``."""
    spec = DATASETS[name]
    rng = np.random.default_rng(seed)
    clips = max(2, int(round(spec["clips"] * scale)))
    pool = rng.standard_normal(1 << 24).astype(np.float16)  # keypoint values drawn from one random pool
    low, high = spec["frames"]
    annotations = []
    for i in tqdm(range(clips), desc=f"synthetic {name}", unit="clip", disable=None):
        bodies = 2 if rng.random() < spec["two_bodies"] else 1
        frames = int(rng.integers(low, high + 1))
        size = bodies * frames * spec["joints"]
        start = int(rng.integers(0, len(pool) - size * spec["channels"]))
        keypoint = (
            pool[start : start + size * spec["channels"]].reshape(bodies, frames, spec["joints"], -1).copy()
        )
        anno = {"frame_dir": f"{name}_{i:06d}", "label": int(rng.integers(spec["classes"])),
                "total_frames": frames, "keypoint": keypoint}  # fmt: skip
        if spec["channels"] == 2:
            anno["keypoint_score"] = np.abs(pool[start : start + size]).reshape(bodies, frames, -1).copy()
            anno["img_shape"] = (340, 256)
        annotations.append(anno)
    train = int(clips * spec["train_share"])
    names = [a["frame_dir"] for a in annotations]
    data = {"split": {"train": names[:train], "val": names[train:]}, "annotations": annotations}
    with open(path, "wb") as handle:  # protocol 5: no transient copy of each array kept in the pickler's memo
        pickle.dump(data, handle, protocol=5)


_BUILD = """
import json, sys, time
from skeleton_mamba.tasks.recognition.keypoint_store import ensure_store
start = time.perf_counter()
store = ensure_store(sys.argv[1], sys.argv[2])
seconds = time.perf_counter() - start
peak = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")) / 1024
size = sum(p.stat().st_size for p in store.folder.iterdir()) / 2**20
print(json.dumps({"seconds": seconds, "peak_mb": peak, "store_mb": size}))
"""


def rank_main(args: argparse.Namespace) -> None:
    """One rank (run as a child of this script): set up the data module, read its share of one epoch."""
    import torch
    from torch.utils.data import DataLoader, DistributedSampler

    from skeleton_mamba.tasks.recognition.data import RecognitionDataModule

    torch.set_num_threads(1)
    spec = DATASETS[args.dataset]
    before = _memory()
    start = time.perf_counter()
    dm = RecognitionDataModule(args.ann_file, num_classes=spec["classes"], skeleton=spec["skeleton"],
                               train_split="train", val_split="val", num_workers=args.workers,
                               batch_size=args.batch_size, memory_map=args.mode == "store",
                               store_dir=args.store_dir)  # fmt: skip
    dm.setup("fit")
    setup_s = time.perf_counter() - start
    after = _memory()
    dataset = dm.datasets["train"]
    sampler = DistributedSampler(dataset, num_replicas=args.world, rank=args.rank, shuffle=True, seed=0)
    loader = DataLoader(dataset, batch_size=args.batch_size, sampler=sampler, num_workers=args.workers,
                        drop_last=True, persistent_workers=False)  # fmt: skip
    total = len(loader) if args.batches <= 0 else min(args.batches, len(loader))
    waits, workers_first = [], None
    batches = iter(loader)
    for i in range(total):
        tick = time.perf_counter()
        next(batches)
        waits.append(time.perf_counter() - tick)
        if i == 0:
            workers_first = [_memory(p) for p in _children(os.getpid())]
    workers_last = [_memory(p) for p in _children(os.getpid())]
    result = {
        "rank": args.rank, "setup_s": setup_s,
        "data_private_mb": after["private_dirty"] - before["private_dirty"],
        "after_setup": after, "workers_first_batch": workers_first, "workers_end": workers_last,
        "batches": total, "batch_wait_median_ms": 1000 * statistics.median(waits),
        "batch_wait_p95_ms": 1000 * float(np.percentile(waits, 95)), "epoch_s": sum(waits),
    }  # fmt: skip
    del batches
    print(json.dumps(result))


def _ranks(ann: Path, store_dir: Path, dataset: str, mode: str, world: int, args: argparse.Namespace) -> list:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    common = ["--ann-file", str(ann), "--store-dir", str(store_dir), "--dataset", dataset, "--mode", mode,
              "--world", str(world), "--workers", str(args.workers), "--batch-size", str(args.batch_size),
              "--batches", str(args.batches)]  # fmt: skip
    procs = [
        subprocess.Popen(
            [sys.executable, __file__, "--rank-child", str(rank), *common],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        for rank in range(world)
    ]
    results = []
    for proc in procs:
        out, _ = proc.communicate()
        if proc.returncode != 0:
            raise RuntimeError(f"rank child failed ({mode}, {world} ranks)")
        results.append(json.loads(out.strip().splitlines()[-1]))
    return results


def _print_rank(mode: str, world: int, r: dict) -> None:
    private = [round(w["private_dirty"]) for w in r["workers_end"]]
    grown = [round(e["private_dirty"] - f["private_dirty"])
             for f, e in zip(r["workers_first_batch"], r["workers_end"], strict=False)]  # fmt: skip
    print(f"  {mode:6s} {world} rank(s), rank {r['rank']}: setup {r['setup_s']:.1f} s, data held "
          f"privately {r['data_private_mb']:.0f} MB, PSS {r['after_setup']['pss']:.0f} MB; workers private "
          f"{private} MB (grew {grown} over {r['batches']} batches); batch wait median "
          f"{r['batch_wait_median_ms']:.1f} ms, p95 {r['batch_wait_p95_ms']:.1f} ms", flush=True)  # fmt: skip


MODES = {"store": "memory-mapped store", "pickle": "pickle in each process"}


def span(values: list[float], unit: str) -> str:
    """``low to high unit`` over the ranks (one value alone when they agree to the printed digits)."""
    digits = 1 if unit == "s" else 0
    low, high = f"{min(values):,.{digits}f}", f"{max(values):,.{digits}f}"
    return f"{low} {unit}" if low == high else f"{low} to {high} {unit}"


def table(report: dict) -> str:
    """The markdown table of ``benchmarks/README.md`` from a report (``--table`` prints it)."""
    lines = [
        "| data set | keypoints read from | ranks | setup per rank | data held privately per rank | "
        "PSS per rank | workers' growth over the epoch | batch wait median (p95) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, entry in report["datasets"].items():
        data, built = entry["data"], entry["build"]
        lines.append(f"| {name}: {data['clips']:,} clips, {data['file_mb']:,.0f} MB | store built once: "
                     f"{built['seconds']:.1f} s, peak {built['peak_mb']:,.0f} MB | | | | | | |")  # fmt: skip
        for key, ranks in entry.items():
            mode, _, world = key.partition("_")
            if mode not in MODES:
                continue
            if isinstance(ranks, dict):  # skipped: why
                lines.append(f"| {name} | {MODES[mode]} | {world} | not run: {ranks['skipped']} | | | | |")
                continue
            growth = [e["private_dirty"] - f["private_dirty"] for r in ranks
                      for f, e in zip(r["workers_first_batch"], r["workers_end"], strict=False)]  # fmt: skip
            waits = "; ".join(
                f"{r['batch_wait_median_ms']:.0f} ({r['batch_wait_p95_ms']:.0f}) ms" for r in ranks
            )
            lines.append(
                f"| {name} | {MODES[mode]} | {world} | {span([r['setup_s'] for r in ranks], 's')} | "
                f"{span([r['data_private_mb'] for r in ranks], 'MB')} | "
                f"{span([r['after_setup']['pss'] for r in ranks], 'MB')} | "
                f"{span(growth, 'MB')} over {ranks[0]['batches']} batches | {waits} |"
            )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="write bench_recognition_scale.json beside")
    parser.add_argument("--datasets", nargs="+", default=list(DATASETS), choices=list(DATASETS))
    parser.add_argument("--scale", type=float, default=1.0, help="fraction of the data set's clips")
    parser.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--modes", nargs="+", default=["store", "pickle"], choices=["store", "pickle"])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--batch-size", type=int, default=128)
    parser.add_argument("--batches", type=int, default=0, help="batches per rank (0: the whole epoch)")
    parser.add_argument(
        "--work", type=Path, default=None, help="folder for the files (default: a temporary one)"
    )
    parser.add_argument("--reuse", action="store_true", help="use the annotation files already in --work")
    parser.add_argument("--merge", action="store_true", help="keep the JSON's other data sets")
    # a rank (internal)
    parser.add_argument("--rank-child", type=int, default=None, help=argparse.SUPPRESS)
    for name in ("--ann-file", "--store-dir", "--dataset", "--mode"):
        parser.add_argument(name, help=argparse.SUPPRESS)
    parser.add_argument("--world", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--table", action="store_true", help="print the README table of the saved JSON")
    args = parser.parse_args()
    if args.table:
        print(table(json.loads(Path(__file__).with_suffix(".json").read_text())))
        return
    if args.rank_child is not None:
        args.rank = args.rank_child
        rank_main(args)
        return
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_recognition_scale-"))
    work.mkdir(parents=True, exist_ok=True)
    report = {"machine": machine_info(), "date": time.strftime("%Y-%m-%d"), "scale": args.scale,
              "workers": args.workers, "batch_size": args.batch_size, "datasets": {}}  # fmt: skip
    if args.merge and Path(__file__).with_suffix(".json").is_file():  # keep the data sets not run again
        earlier = json.loads(Path(__file__).with_suffix(".json").read_text())
        report["datasets"] = {k: v for k, v in earlier["datasets"].items() if k not in args.datasets}
    for name in args.datasets:
        ann, store_dir = work / f"{name}.pkl", work / "stores"
        if not (args.reuse and ann.is_file()):
            # in a child process: its memory goes back to the system before the build and the ranks
            with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
                pool.submit(make_dataset, name, args.scale, ann).result()
        shutil.rmtree(store_folder(ann, store_dir), ignore_errors=True)  # the build is always measured
        build = subprocess.run([sys.executable, "-c", _BUILD, str(ann), str(store_dir)], capture_output=True,
                               text=True, check=True)  # fmt: skip
        entry = {"date": time.strftime("%Y-%m-%d"), "data": describe(ann, store_dir),
                 "build": json.loads(build.stdout.strip().splitlines()[-1])}  # fmt: skip
        data, built = entry["data"], entry["build"]
        print(
            f"{name}: {data['clips']} clips, file {data['file_mb']:.0f} MB; store built in "
            f"{built['seconds']:.1f} s (peak {built['peak_mb']:.0f} MB), {built['store_mb']:.0f} MB",
            flush=True,
        )
        for mode in args.modes:
            for world in args.ranks:
                need = world * PICKLE_COPIES * data["file_mb"]
                if mode == "pickle" and need > _available_mb():
                    why = (f"{world} rank(s) unpickling the file need about {need / 1024:.0f} GB, the "
                           f"machine has {_available_mb() / 1024:.0f} GB available")  # fmt: skip
                    entry[f"{mode}_{world}"] = {"skipped": why}
                    print(f"  {mode:6s} {world} rank(s): skipped, {why}")
                    continue
                entry[f"{mode}_{world}"] = ranks = _ranks(ann, store_dir, name, mode, world, args)
                for r in ranks:
                    _print_rank(mode, world, r)
        report["datasets"][name] = entry
        if not args.reuse:
            ann.unlink()
        if args.json:  # after each data set: a later one running out of memory keeps the earlier ones
            write_report(__file__, report)


if __name__ == "__main__":
    main()
