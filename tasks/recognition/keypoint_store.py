"""One copy of a data set's keypoints per machine: a PYSKL annotation file as memory-mapped arrays.

A PYSKL pickle is read whole by every process that opens it, so 8 DDP ranks on one node held 8 copies of
NTU120 or Kinetics-skeleton. :func:`ensure_store` converts the pickle once (on the node's first rank,
Lightning's ``prepare_data``) into flat arrays that every rank and every loader worker maps read-only: the
operating system's page cache holds the keypoints once per machine, and a process pays privately only for the
small index. PYSKL's pickle stays the input; the store is a cache beside the user's other caches.

A store folder (``<cache>/keypoints/<file stem>-<hash of its path>``; written into a temporary folder and
renamed, so an interrupted build leaves nothing half-written):

- ``keypoint.bin``: every sample's (M, T, V, C) keypoints flattened to M*T rows of (V, C), one sample after
  the other, float16 when every keypoint of the source is float16 (PYSKL's own files), else float32;
- ``keypoint_score.bin``: the (M*T, V) scores of 2D data sets;
- ``index.npz``: per sample ``offset`` (first row), ``bodies`` M, ``frames`` T, ``label``, ``img_shape``
  (H, W; -1 where the source has none) and ``frame_dir``;
- ``store.json``: the source (resolved path, size, modification time), the format version, the dtype and
  (V, C); ``splits.json``: split name -> sample indices.

Every sample is validated while the store is built (:func:`.pyskl.iter_validated`: the same checks as
:func:`.pyskl.load_annotations`), so reading it back checks only that the index fits the arrays. A store is
rebuilt when its source's size or modification time changes. Only the keys the pipeline reads are kept
(``keypoint``, ``keypoint_score``, ``img_shape``, ``label``, ``total_frames``, ``frame_dir``).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from skeleton_mamba.tasks.motion.io.cache import default_cache_root
from skeleton_mamba.tasks.motion.io.safe_pickle import safe_load_pickle
from skeleton_mamba.tasks.recognition.pyskl import (
    AnnotationFileError,
    check_structure,
    iter_validated,
    validate_split,
)

__all__ = ["KeypointStore", "StoreSplit", "build_store", "ensure_store", "store_folder"]

STORE_VERSION = 1
_INDEX_KEYS = ("offset", "bodies", "frames", "label", "img_shape", "frame_dir")


def store_folder(ann_file: str | os.PathLike[str], store_dir: str | os.PathLike[str] | None = None) -> Path:
    """Where the store of ``ann_file`` lives: ``store_dir`` (default ``<cache root>/keypoints``), one
    folder per source path."""
    source = Path(ann_file).expanduser().resolve()
    root = Path(store_dir).expanduser() if store_dir is not None else default_cache_root() / "keypoints"
    return root / f"{source.stem}-{hashlib.sha256(str(source).encode()).hexdigest()[:16]}"


def _source_stamp(ann_file: str | os.PathLike[str]) -> dict[str, Any]:
    source = Path(ann_file).expanduser().resolve()
    stat = source.stat()
    return {
        "source": str(source),
        "size": stat.st_size,
        "mtime_ns": stat.st_mtime_ns,
        "version": STORE_VERSION,
    }


def _img_shape(anno: dict, source: str) -> tuple[int, int]:
    shape = anno.get("img_shape")
    if shape is None:
        return (-1, -1)
    try:
        height, width = (int(v) for v in shape)
    except (TypeError, ValueError):
        what = f"{source}: {anno['frame_dir']}: 'img_shape' must be (H, W), got {shape!r}"
        raise AnnotationFileError(what) from None
    return height, width


def build_store(ann_file: str | os.PathLike[str], folder: str | os.PathLike[str]) -> Path:
    """Convert the PYSKL pickle ``ann_file`` into the store ``folder`` (module docstring); returns it.

    Memory: the unpickled file (PYSKL's pickle cannot be read in parts), released sample by sample as the
    rows are written.

    Raises:
        AnnotationFileError: the file is not a valid PYSKL annotation file (the message names it), or its
            samples do not share one (V, C) layout.
    """
    source, folder = str(ann_file), Path(folder)
    stamp = _source_stamp(ann_file)
    data = safe_load_pickle(ann_file)
    check_structure(data, source)
    annotations = list(data["annotations"])
    data["annotations"] = None  # the list above is the only reference: samples are freed as they are written
    half = bool(annotations) and all(
        getattr(a.get("keypoint") if isinstance(a, dict) else None, "dtype", None) == np.float16
        for a in annotations
    )
    dtype = np.float16 if half else np.float32
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = folder.parent / f".tmp-{folder.name}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        index: dict[str, list] = {key: [] for key in _INDEX_KEYS}
        layout: tuple[int, int] | None = None
        rows = 0
        seen: set[str] = set()
        samples = iter_validated(_consume(annotations), source, seen)
        with open(tmp / "keypoint.bin", "wb") as keypoints, open(tmp / "keypoint_score.bin", "wb") as scores:
            desc = f"memory-mapped copy of {Path(source).name}"
            progress = tqdm(samples, total=len(annotations), desc=desc, unit="sample", disable=None)
            for anno in progress:
                bodies, frames, joints, channels = anno["keypoint"].shape
                if layout is None:
                    layout = (joints, channels)
                elif (joints, channels) != layout:
                    raise AnnotationFileError(
                        f"{source}: {anno['frame_dir']} has keypoints of {joints} joints x {channels} "
                        f"channels, the samples before it {layout[0]} x {layout[1]}: one file, one layout"
                    )
                keypoints.write(anno["keypoint"].astype(dtype).tobytes())
                if "keypoint_score" in anno:
                    scores.write(anno["keypoint_score"].astype(dtype).tobytes())
                elif channels == 2:
                    raise AnnotationFileError(
                        f"{source}: {anno['frame_dir']}: 2D keypoints need keypoint_score"
                    )
                for key, value in zip(
                    _INDEX_KEYS,
                    (rows, bodies, frames, anno["label"], _img_shape(anno, source), anno["frame_dir"]),
                    strict=True,
                ):
                    index[key].append(value)
                rows += bodies * frames
        if layout is None:
            raise AnnotationFileError(f"{source}: no annotations")
        names = {name: i for i, name in enumerate(index["frame_dir"])}
        splits = {k: [names[n] for n in v] for k, v in validate_split(data["split"], seen, source).items()}
        with open(tmp / "index.npz", "wb") as handle:
            np.savez(handle, **{key: np.asarray(index[key]) for key in _INDEX_KEYS})
        (tmp / "splits.json").write_text(json.dumps(splits))
        score_bytes = (tmp / "keypoint_score.bin").stat().st_size
        if score_bytes not in (0, rows * layout[0] * np.dtype(dtype).itemsize):
            raise AnnotationFileError(f"{source}: some samples have keypoint_score, others not")
        meta = {**stamp, "dtype": np.dtype(dtype).name, "rows": rows, "joints": layout[0],
                "channels": layout[1], "scores": score_bytes > 0}  # fmt: skip
        (tmp / "store.json").write_text(json.dumps(meta, indent=1))
        if folder.exists():
            _remove_store(folder)
        os.replace(tmp, folder)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return folder


def _consume(items: list) -> Iterator[Any]:
    """Yield the list's items, dropping each from the list as it is taken (its memory freed once used)."""
    for i in range(len(items)):
        item, items[i] = items[i], None
        yield item


def _remove_store(folder: Path) -> None:
    """Remove an earlier store, and only a store: a folder of exactly the store's files."""
    expected = {"keypoint.bin", "keypoint_score.bin", "index.npz", "splits.json", "store.json"}
    found = {p.name for p in folder.iterdir()}
    if folder.is_symlink() or not found <= expected or "store.json" not in found:
        other = sorted(found - expected)[:3]
        raise AnnotationFileError(f"{folder}: not a keypoint store (it holds {other}); move it away or "
                                  "choose another store_dir")  # fmt: skip
    shutil.rmtree(folder)


@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """One builder per store on this machine (ranks of several data modules, or runs started together)."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(folder.parent / f".{folder.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def ensure_store(
    ann_file: str | os.PathLike[str], store_dir: str | os.PathLike[str] | None = None
) -> KeypointStore:
    """The store of ``ann_file``, built first when it is missing or its source changed since."""
    folder = store_folder(ann_file, store_dir)
    stamp = _source_stamp(ann_file)
    with _locked(folder):
        if not _fresh(folder, stamp):
            build_store(ann_file, folder)
    return KeypointStore(folder, str(ann_file))


def _fresh(folder: Path, stamp: dict[str, Any]) -> bool:
    try:
        meta = json.loads((folder / "store.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and all(meta.get(key) == value for key, value in stamp.items())


class KeypointStore:
    """A built store (module docstring), its arrays mapped read-only.

    Args:
        folder: the store folder.
        source: how to name the data in error messages (the annotation file).

    Raises:
        AnnotationFileError: the folder is not a complete store, or its index does not fit its arrays.
    """

    def __init__(self, folder: str | os.PathLike[str], source: str | None = None) -> None:
        self.folder = Path(folder)
        self.source = source or str(self.folder)
        try:
            meta = json.loads((self.folder / "store.json").read_text())
            with np.load(self.folder / "index.npz", allow_pickle=False) as index:
                arrays = {key: index[key] for key in _INDEX_KEYS}
            splits = json.loads((self.folder / "splits.json").read_text())
            rows, joints, channels, dtype = (
                meta["rows"],
                meta["joints"],
                meta["channels"],
                np.dtype(meta["dtype"]),
            )
            self.keypoint = np.memmap(
                self.folder / "keypoint.bin", dtype, "r", shape=(rows, joints, channels)
            )
            self.keypoint_score = (
                np.memmap(self.folder / "keypoint_score.bin", dtype, "r", shape=(rows, joints))
                if meta["scores"] else None
            )  # fmt: skip
        except (OSError, ValueError, KeyError, TypeError) as err:
            raise AnnotationFileError(f"{self.folder}: not a complete keypoint store ({err}); delete it to "
                                      "rebuild it from the annotation file") from None  # fmt: skip
        self.meta = meta
        self.offset, self.bodies, self.frames = (
            arrays[k].astype(np.int64) for k in ("offset", "bodies", "frames")
        )
        self.labels = arrays["label"].astype(np.int64)
        self.img_shape = arrays["img_shape"].astype(np.int64)
        self.frame_dirs = arrays["frame_dir"]
        n = len(self.offset)
        ends = self.offset + self.bodies * self.frames
        fits = all(len(arrays[k]) == n for k in _INDEX_KEYS) and self.img_shape.shape == (n, 2)
        if not fits or n == 0 or (ends > rows).any() or (self.offset < 0).any() or (self.labels < 0).any():
            raise AnnotationFileError(f"{self.folder}: the store's index does not fit its arrays; delete the "
                                      "folder to rebuild it from the annotation file")  # fmt: skip
        self.splits = {name: np.asarray(members, dtype=np.int64) for name, members in splits.items()}
        if any(((m < 0) | (m >= n)).any() for m in self.splits.values()):
            raise AnnotationFileError(f"{self.folder}: a split names a sample outside the store")

    def __len__(self) -> int:
        return len(self.offset)

    @property
    def num_joints(self) -> int:
        return int(self.meta["joints"])

    def annotation(self, index: int) -> dict[str, Any]:
        """Sample ``index`` as a PYSKL annotation dict, its arrays float32 copies (M, T, V, C)."""
        start, bodies, frames = int(self.offset[index]), int(self.bodies[index]), int(self.frames[index])
        rows = slice(start, start + bodies * frames)
        anno: dict[str, Any] = {
            "frame_dir": str(self.frame_dirs[index]),
            "label": int(self.labels[index]),
            "total_frames": frames,
            "keypoint": np.asarray(self.keypoint[rows], dtype=np.float32).reshape(
                bodies, frames, *self.keypoint.shape[1:]
            ),
        }
        if self.keypoint_score is not None:
            anno["keypoint_score"] = np.asarray(self.keypoint_score[rows], dtype=np.float32).reshape(
                bodies, frames, -1
            )
        if self.img_shape[index, 0] >= 0:
            anno["img_shape"] = tuple(int(v) for v in self.img_shape[index])
        return anno

    def split(self, name: str) -> StoreSplit:
        """The samples of split ``name`` in the split's order."""
        return StoreSplit(self, self.splits[name])

    def __getstate__(self) -> dict[str, Any]:
        """Pickled by folder (a loader worker started by ``spawn`` maps the files again, copying nothing)."""
        return {"folder": str(self.folder), "source": self.source}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["folder"], state["source"])


class StoreSplit(Sequence):
    """Samples ``indices`` of a :class:`KeypointStore` as a sequence of annotation dicts, read on access."""

    def __init__(self, store: KeypointStore, indices: np.ndarray) -> None:
        self.store = store
        self.indices = indices

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, i):  # noqa: ANN001 - int or slice, as a Sequence
        if isinstance(i, slice):
            return StoreSplit(self.store, self.indices[i])
        return self.store.annotation(int(self.indices[i]))

    @property
    def labels(self) -> np.ndarray:
        return self.store.labels[self.indices]

    @property
    def sample_names(self) -> list[str]:
        return self.store.frame_dirs[self.indices].tolist()
