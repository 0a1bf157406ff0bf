"""``sm prepare``: raw NTU RGB+D / Kinetics-skeleton files -> one PYSKL annotation pickle.

::

    sm prepare ntu60  --raw nturgb+d_skeletons/ --out data/ntu60_3danno.pkl [--workers 2] [--skip-bad]
                      [--dtype float32|float16]
    sm prepare ntu120 --raw nturgb+d_skeletons/ --out data/ntu120_3danno.pkl
    sm prepare kinetics --raw kinetics-skeleton/ --out data/kinetics_2d.pkl [--labels A.json B.json]

NTU: every ``*.skeleton`` under ``--raw`` (sub-folders included, so both NTU120 zips may be unpacked side
by side) is parsed in parallel with :func:`.ntu.read_skeleton_file`; the bodies are chosen as PYSKL's
``ntu_preproc.py`` does (:meth:`.ntu.NTUSequence.keypoints`), ``label = action - 1``, and the official
samples with missing skeletons are left out. Samples outside the dataset (NTU120 setups or actions when
preparing NTU60) are ignored. Splits: ``xsub_train xsub_val xview_train xview_val`` (NTU60),
``xsub_train xsub_val xset_train xset_val`` (NTU120).

Kinetics: ``--raw`` holds ST-GCN's ``kinetics_train/`` and ``kinetics_val/`` (one JSON per clip) and, unless
``--labels`` names them, ``kinetics_{train,val}_label.json``. Clips whose label entry says
``has_skeleton: false`` are skipped (ST-GCN ``ignore_empty_sample``). Splits: ``train`` and ``val``.
Keypoints stay in ST-GCN's [0, 1] coordinates (``img_shape`` (1, 1), ``original_shape`` (256, 340)).

Keypoints are stored as float32 by default; ``--dtype float16`` writes them as PYSKL's own annotation files
do (tools/data/ntu_preproc.py), half the size. A file that fails to parse stops the command with its name
and line, unless ``--skip-bad`` is given.
"""

from __future__ import annotations

import multiprocessing
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from tqdm import tqdm

from skeleton_mamba.errors import SkeletonMambaError, worker_ignores_ctrl_c
from skeleton_mamba.tasks.motion.formats.ntu import SkeletonFileError, parse_ntu_name, read_skeleton_file
from skeleton_mamba.tasks.recognition.kinetics import (
    KineticsFileError,
    read_kinetics_clip,
    read_kinetics_labels,
)
from skeleton_mamba.tasks.recognition.prepare_args import build_parser
from skeleton_mamba.tasks.recognition.pyskl import save_annotations
from skeleton_mamba.tasks.recognition.splits import benchmark_splits, in_dataset, load_missing_samples

__all__ = ["build_parser", "main", "prepare_kinetics", "prepare_ntu"]

KINETICS_PARTS = ("train", "val")
KINETICS_FRAME_SHAPE = (256, 340)  # ST-GCN resized the videos to 340x256 before OpenPose


class PrepareError(SkeletonMambaError, RuntimeError):
    """A raw file could not be converted (its message names the file and what is wrong)."""


def _ntu_annotation(path: str, max_bodies: int) -> tuple[str, dict | None, str | None]:
    """Worker: one ``.skeleton`` file -> (name, annotation or None when it has no body, error or None)."""
    name = Path(path).name.split(".")[0]
    try:
        keypoint = read_skeleton_file(path).keypoints(max_bodies)
    except (SkeletonFileError, OSError) as e:
        return name, None, str(e)
    if keypoint.shape[1] == 0:
        return name, None, None
    anno = {"frame_dir": name, "label": parse_ntu_name(name)["action"] - 1, "keypoint": keypoint,
            "total_frames": int(keypoint.shape[1])}  # fmt: skip
    return name, anno, None


def _kinetics_annotation(path: str, expected_label: int) -> tuple[str, dict | None, str | None]:
    """Worker: one clip JSON -> (video_id, annotation or None when nobody is detected, error or None)."""
    video_id = Path(path).stem
    try:
        keypoint, score, label, label_name = read_kinetics_clip(path)
    except (KineticsFileError, OSError) as e:
        return video_id, None, str(e)
    if label != expected_label:
        return video_id, None, f"{path}: label_index {label} differs from {expected_label} in the label file"
    if keypoint.shape[0] == 0 or not score.any():
        return video_id, None, None
    anno = {"frame_dir": video_id, "label": label, "keypoint": keypoint, "keypoint_score": score,
            "total_frames": int(keypoint.shape[1]), "img_shape": (1, 1),
            "original_shape": KINETICS_FRAME_SHAPE, "label_name": label_name}  # fmt: skip
    return video_id, anno, None


def _run(
    worker: Callable[..., tuple[str, dict | None, str | None]],
    jobs: list[tuple],
    workers: int,
    skip_bad: bool,
    desc: str,
    progress: bool = True,
) -> tuple[dict[str, dict], list[str], list[str]]:
    """Run ``worker(*job)`` over ``jobs`` with a process pool and a progress bar (unless not ``progress``).

    Returns:
        (annotations by name, names without any body, error messages of skipped files).

    Raises:
        PrepareError: a file failed and ``skip_bad`` is False (the pool is stopped at once).
    """
    annotations: dict[str, dict] = {}
    empty: list[str] = []
    bad: list[str] = []
    chunksize = max(1, min(16, len(jobs) // (4 * workers)))

    def results(pool) -> Iterator:
        if pool is None:
            return (worker(*job) for job in jobs)
        return pool.imap(_star, [(worker, job) for job in jobs], chunksize=chunksize)

    pool = multiprocessing.Pool(workers, initializer=worker_ignores_ctrl_c) if workers > 1 else None
    try:
        bar = tqdm(
            results(pool), total=len(jobs), desc=desc, unit="file", file=sys.stderr, disable=not progress
        )
        for name, anno, error in bar:
            if error is not None:
                if not skip_bad:
                    raise PrepareError(f"{error}\n(use --skip-bad to skip unreadable files with a warning)")
                tqdm.write(f"warning: skipping {name}: {error}", file=sys.stderr)
                bad.append(error)
            elif anno is None:
                tqdm.write(f"warning: skipping {name}: no body in any frame", file=sys.stderr)
                empty.append(name)
            else:
                annotations[name] = anno
    finally:
        if pool is not None:
            pool.terminate()
            pool.join()
    return annotations, empty, bad


def _check_some_written(count: int, out: Path, **skipped: int) -> None:
    """Refuse to write an annotation file without samples (``out`` keeps its old content)."""
    if count == 0:
        why = ", ".join(f"{v} {k}" for k, v in skipped.items())
        raise PrepareError(f"no usable sample ({why}); {out} was not written")


def _star(item: tuple) -> tuple:
    worker, job = item
    return worker(*job)


def prepare_ntu(dataset: str, raw: Path, out: Path, workers: int = 2, skip_bad: bool = False,
                max_bodies: int = 2, dtype: str = "float32", progress: bool = True) -> dict:  # fmt: skip
    """Build the PYSKL annotation file of ``dataset`` ("ntu60" or "ntu120") from raw ``.skeleton`` files.

    ``dtype``: keypoint storage, ``"float32"`` or ``"float16"`` (as PYSKL's files; see
    :func:`.pyskl.save_annotations`). ``progress``: show a progress bar.

    Returns:
        A summary: counts of ``written``, ``missing_excluded``, ``outside_dataset``, ``empty`` and
        ``bad`` samples and the size of each split.
    """
    if not raw.is_dir():
        raise PrepareError(f"{raw}: the --raw folder does not exist")
    files: dict[str, Path] = {}
    for path in sorted(raw.rglob("*.skeleton")):
        name = path.name.split(".")[0]
        try:
            parse_ntu_name(name)
        except ValueError as e:
            if not skip_bad:
                raise PrepareError(f"{e} (use --skip-bad to ignore such files)") from None
            print(f"warning: skipping {path}: not an NTU sample name", file=sys.stderr)
            continue
        if name in files:
            raise PrepareError(f"sample {name} found twice: {files[name]} and {path}")
        files[name] = path
    if not files:
        raise PrepareError(f"{raw}: no .skeleton files found (expected the unpacked NTU RGB+D skeleton zip)")
    missing = load_missing_samples(dataset)
    inside = [n for n in files if in_dataset(n, dataset)]
    selected = [n for n in inside if n not in missing]
    jobs = [(str(files[n]), max_bodies) for n in selected]
    annos, empty, bad = _run(_ntu_annotation, jobs, workers, skip_bad, f"prepare {dataset}", progress)
    names = sorted(annos)
    _check_some_written(len(names), out, empty=len(empty), bad=len(bad))
    split = benchmark_splits(names, dataset)
    save_annotations({"split": split, "annotations": [annos[n] for n in names]}, out, dtype)
    return {"written": len(names), "missing_excluded": len(inside) - len(selected),
            "outside_dataset": len(files) - len(inside), "empty": len(empty), "bad": len(bad),
            "splits": {k: len(v) for k, v in split.items()}}  # fmt: skip


def prepare_kinetics(raw: Path, out: Path, labels: Sequence[Path] | None = None, workers: int = 2,
                     skip_bad: bool = False, dtype: str = "float32",
                     progress: bool = True) -> dict:  # fmt: skip
    """Build a PYSKL 2D annotation file from ST-GCN's Kinetics-skeleton folders (``dtype``, ``progress`` as
    NTU's).

    Returns:
        A summary: counts of ``written``, ``no_skeleton`` (label file says so), ``empty`` and ``bad`` clips
        and the size of each split.
    """
    parts = [p for p in KINETICS_PARTS if (raw / f"kinetics_{p}").is_dir()]
    if not parts:
        raise PrepareError(f"{raw}: neither kinetics_train/ nor kinetics_val/ found (ST-GCN layout)")
    label_files = list(labels) if labels else [raw / f"kinetics_{p}_label.json" for p in parts]
    label_info: dict[str, dict] = {}
    for path in label_files:
        if not path.is_file():
            raise PrepareError(f"{path}: label file not found (give it with --labels)")
        label_info.update(read_kinetics_labels(path))
    split: dict[str, list[str]] = {}
    annotations: list[dict] = []
    summary = {"written": 0, "no_skeleton": 0, "empty": 0, "bad": 0}
    for part in parts:
        jobs = []
        for path in sorted((raw / f"kinetics_{part}").glob("*.json")):
            entry = label_info.get(path.stem)
            if entry is None:
                known = ", ".join(map(str, label_files))
                raise PrepareError(f"{path}: clip {path.stem!r} has no entry in {known}")
            if not entry["has_skeleton"]:
                summary["no_skeleton"] += 1
                continue
            jobs.append((str(path), int(entry["label_index"])))
        annos, empty, bad = _run(
            _kinetics_annotation, jobs, workers, skip_bad, f"prepare kinetics {part}", progress
        )
        split[part] = sorted(annos)
        annotations += [annos[n] for n in split[part]]
        summary["empty"] += len(empty)
        summary["bad"] += len(bad)
    names = {e["label_index"]: e.get("label", "") for e in label_info.values()}
    label_names = [names.get(i, "") for i in range(max(names, default=-1) + 1)]
    _check_some_written(len(annotations), out, empty=summary["empty"], bad=summary["bad"])
    save_annotations({"split": split, "annotations": annotations, "label_names": label_names}, out, dtype)
    summary["written"] = len(annotations)
    summary["splits"] = {k: len(v) for k, v in split.items()}
    return summary


def main(argv: Sequence[str] | None = None) -> int:
    """``sm prepare`` entry point; returns the exit code."""
    args = build_parser().parse_args(argv)
    if args.workers < 1:
        raise PrepareError(f"--workers {args.workers}: must be >= 1")
    if args.dataset == "kinetics":  # PrepareError, AnnotationFileError: sm prints one line, exit 2
        summary = prepare_kinetics(
            args.raw, args.out, args.labels, args.workers, args.skip_bad, args.dtype, args.progress
        )
    else:
        summary = prepare_ntu(
            args.dataset,
            args.raw,
            args.out,
            args.workers,
            args.skip_bad,
            args.max_bodies,
            args.dtype,
            args.progress,
        )
    splits = ", ".join(f"{k} {v}" for k, v in summary.pop("splits").items())
    print(f"wrote {summary.pop('written')} samples to {args.out} ({splits})")
    print("; ".join(f"{k.replace('_', ' ')}: {v}" for k, v in summary.items()))
    return 0
