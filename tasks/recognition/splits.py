"""Official NTU RGB+D 60 / 120 benchmarks: split membership of a sample and the missing-skeleton lists.

Package data beside this module:

- ``ntu_splits.json``: training subjects (X-Sub), cameras (NTU60 X-View) and setups (NTU120 X-Set), from
  CTR-GCN ``data/ntu/seq_transformation.py`` / ST-GCN ``tools/ntu_gendata.py`` (NTU60) and PYSKL
  ``tools/data/ntu_preproc.py`` (NTU120). Every other id is on the evaluation side.
- ``ntu60_missing_skeletons.txt`` / ``ntu120_missing_skeletons.txt``: the dataset authors' lists of
  samples with missing or incomplete skeletons (``shahroudy/NTURGB-D Matlab/
  NTU_RGBD_samples_with_missing_skeletons.txt``, 302 names, and ``NTU_RGBD120_samples_with_missing_
  skeletons.txt``, 535 names), shipped verbatim with their two header lines.

Split names follow PYSKL: ``xsub_train, xsub_val, xview_train, xview_val`` (NTU60) and
``xsub_train, xsub_val, xset_train, xset_val`` (NTU120). NTU60 is setups S001-S017 with actions A001-A060.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from functools import cache
from importlib.resources import files

from skeleton_mamba.tasks.motion.formats.ntu import parse_ntu_name

__all__ = [
    "DATASETS",
    "BENCHMARKS",
    "benchmark_splits",
    "in_dataset",
    "load_missing_samples",
    "sample_splits",
    "split_names",
    "split_ids",
]

DATASETS = ("ntu60", "ntu120")
BENCHMARKS = {"ntu60": ("xsub", "xview"), "ntu120": ("xsub", "xset")}
_PACKAGE = "skeleton_mamba.tasks.recognition"
_MISSING_FILES = {"ntu60": "ntu60_missing_skeletons.txt", "ntu120": "ntu120_missing_skeletons.txt"}
_NAME_LINE = re.compile(r"S\d{3}C\d{3}P\d{3}R\d{3}A\d{3}")


def _check(dataset: str) -> None:
    if dataset not in DATASETS:
        raise ValueError(f"unknown NTU dataset {dataset!r}; expected one of {DATASETS}")


@cache
def split_ids(dataset: str) -> dict:
    """The training ids of ``dataset`` from ``ntu_splits.json`` (``xsub_train_subjects``, ...)."""
    _check(dataset)
    return json.loads(files(_PACKAGE).joinpath("ntu_splits.json").read_text())[dataset]


@cache
def load_missing_samples(dataset: str) -> frozenset[str]:
    """The official samples with missing or incomplete skeletons (302 for NTU60, 535 for NTU120)."""
    _check(dataset)
    text = files(_PACKAGE).joinpath(_MISSING_FILES[dataset]).read_text()
    return frozenset(line.strip() for line in text.splitlines() if _NAME_LINE.fullmatch(line.strip()))


def split_names(dataset: str) -> tuple[str, ...]:
    """The PYSKL split names of ``dataset`` in their usual order."""
    _check(dataset)
    return tuple(f"{b}_{part}" for b in BENCHMARKS[dataset] for part in ("train", "val"))


def in_dataset(name: str, dataset: str) -> bool:
    """Whether sample ``name`` belongs to ``dataset`` (NTU60: setups 1-17 and actions 1-60)."""
    ids = split_ids(dataset)
    info = parse_ntu_name(name)
    (s_lo, s_hi), (a_lo, a_hi) = ids["setups"], ids["actions"]
    return s_lo <= info["setup"] <= s_hi and a_lo <= info["action"] <= a_hi


def sample_splits(name: str, dataset: str) -> tuple[str, ...]:
    """The splits sample ``name`` belongs to, one per benchmark, e.g. ``("xsub_train", "xview_val")``.

    Raises:
        ValueError: ``name`` is not an NTU name or is outside ``dataset`` (e.g. A061 in NTU60).
    """
    if not in_dataset(name, dataset):
        raise ValueError(f"{name}: not a sample of {dataset} (setups/actions {split_ids(dataset)['setups']}, "
                         f"{split_ids(dataset)['actions']})")  # fmt: skip
    ids = split_ids(dataset)
    info = parse_ntu_name(name)
    train = {
        "xsub": info["performer"] in ids["xsub_train_subjects"],
        "xview": info["camera"] in ids.get("xview_train_cameras", ()),
        "xset": info["setup"] in ids.get("xset_train_setups", ()),
    }
    return tuple(f"{b}_{'train' if train[b] else 'val'}" for b in BENCHMARKS[dataset])


def benchmark_splits(names: Iterable[str], dataset: str) -> dict[str, list[str]]:
    """Group sample names into the PYSKL ``split`` dict of ``dataset`` (input order kept in each list)."""
    split: dict[str, list[str]] = {key: [] for key in split_names(dataset)}
    for name in names:
        for key in sample_splits(name, dataset):
            split[key].append(name)
    return split
