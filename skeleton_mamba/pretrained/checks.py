"""Checks of a pretrained folder before anything is allocated: sizes, the safetensors header, the tensors.

A folder from outside is checked in this order (``PretrainedMixin.from_pretrained`` of
:mod:`skeleton_mamba.pretrained.mixin`, and the commands' folder loader, ``tasks/training/pretrained.py``):

1. ``config.json`` is read by the bounded reader (:mod:`skeleton_mamba.io.bounded_read`: a regular file of at
   most :data:`MAX_CONFIG_BYTES`, nesting, finite numbers);
2. every size it states is within :data:`~skeleton_mamba.pretrained.size_bounds.SIZE_BOUNDS`
   (:func:`check_sizes`; widths, depths, state sizes, heads, layer and class counts, about 30x [EgoMusic]
   supp. Table 2's sizes), so the network can be built on PyTorch's ``meta`` device (shapes, no memory) in
   bounded time;
3. the network built on ``meta`` (:func:`meta_state`) holds at most :data:`MAX_PARAMETERS` values;
4. the safetensors header is parsed here (:func:`read_safetensors_header`: an 8-byte length of at most
   :data:`MAX_HEADER_BYTES`, then JSON of at most :data:`MAX_TENSORS` entries, each with a known dtype, a
   shape and byte offsets that tile the file's data exactly) and compared with the ``meta`` network
   (:func:`check_header_fits`: the same names and shapes; a floating tensor stored as a floating type,
   any other with its own type);
5. only then are the tensors read (the memory is what the file holds) and checked finite
   (:func:`check_finite_weights`) before any is copied into the network.
"""

from __future__ import annotations

import dataclasses
import math
import os
import struct
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from os import PathLike
from typing import Any

import torch

from skeleton_mamba.io.bounded_read import parse_json
from skeleton_mamba.pretrained.size_bounds import SIZE_BOUNDS, size_bound

__all__ = [
    "MAX_CONFIG_BYTES",
    "MAX_HEADER_BYTES",
    "MAX_PARAMETERS",
    "MAX_TENSORS",
    "SAFETENSORS_DTYPES",
    "SIZE_BOUNDS",
    "HeaderEntry",
    "building_on_meta",
    "check_finite_weights",
    "check_header_fits",
    "check_sizes",
    "dtype_fits",
    "meta_state",
    "read_safetensors_header",
    "size_bound",
]

MAX_CONFIG_BYTES = 1 << 20  # a config.json: a few KiB with a module's hyper-parameters
MAX_HEADER_BYTES = 16 << 20  # a safetensors header; the paper's EMM needs about 60 KiB
MAX_TENSORS = 100_000  # tensors of one weights file; the paper's EMM has about 800
MAX_PARAMETERS = 1_000_000_000  # values of one network (4 GB in fp32); the paper's EMM has 66 M

# safetensors dtype names -> torch dtypes (the types this project writes and reads)
SAFETENSORS_DTYPES: dict[str, torch.dtype] = {
    "F64": torch.float64,
    "F32": torch.float32,
    "F16": torch.float16,
    "BF16": torch.bfloat16,
    "I64": torch.int64,
    "I32": torch.int32,
    "I16": torch.int16,
    "I8": torch.int8,
    "U8": torch.uint8,
    "BOOL": torch.bool,
}


def _items(value: Any) -> Iterator[tuple[str, Any]]:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        yield from ((f.name, getattr(value, f.name)) for f in dataclasses.fields(value))
    elif isinstance(value, Mapping):
        yield from ((str(k), v) for k, v in value.items())


def check_sizes(value: Any, source: str, error: type[Exception] = ValueError) -> None:
    """Refuse a size in ``value`` (dataclasses, mappings and lists, walked without recursion) outside
    ``0 .. size_bound(name)``: one line naming ``source``, where the size is, its value and its bound."""
    stack: list[tuple[str, Any]] = [("", value)]
    while stack:
        where, item = stack.pop()
        for name, child in _items(item):
            path = f"{where}.{name}" if where else name
            bound = size_bound(name)
            numbers = child if isinstance(child, (list, tuple)) else [child]
            if bound is not None:
                for number in numbers:
                    if not isinstance(number, (int, float)) or isinstance(number, bool):
                        continue  # a mapping is walked below; None, strings and flags are no sizes
                    if not isinstance(number, int) or not 0 <= number <= bound:
                        shown = repr(number) if len(repr(number)) <= 30 else repr(number)[:27] + "..."
                        raise error(f"{source}: {path} = {shown}: a size is an integer from 0 to {bound:,}")
            stack.append((path, child))
            if isinstance(child, (list, tuple)):
                stack.extend((f"{path}[{i}]", c) for i, c in enumerate(child))


def building_on_meta() -> bool:
    """True inside a ``meta`` build (:func:`meta_state`): a network that loads pretrained parts from files
    then builds their architecture only (their weights are not the folder's and nothing is read)."""
    return torch.empty(0).device.type == "meta"


def meta_state(cls: type, kwargs: Mapping[str, Any]) -> dict[str, torch.Tensor]:
    """The ``state_dict`` of ``cls(**kwargs)`` built on the ``meta`` device: names, shapes and dtypes, no
    memory. Construction errors propagate (the caller names its file)."""
    with torch.device("meta"):
        return dict(cls(**kwargs).state_dict())


@dataclass(frozen=True)
class HeaderEntry:
    """One tensor of a safetensors header: its dtype, shape and byte range in the data section."""

    dtype: torch.dtype
    shape: tuple[int, ...]
    begin: int
    end: int


def read_safetensors_header(
    path: str | PathLike[str], error: type[Exception] = ValueError
) -> dict[str, HeaderEntry]:
    """The tensors a safetensors file declares, checked against its size before any tensor is read.

    Layout (safetensors' format): an unsigned 64-bit little-endian header length N, N bytes of JSON
    ``{name: {"dtype", "shape", "data_offsets": [begin, end]}, "__metadata__": {str: str}}``, then the
    data, which the tensors' byte ranges must tile exactly.

    Raises:
        error: naming ``path`` and the entry at fault.
        OSError: missing or unreadable.
    """
    name = os.fspath(path)
    with open(name, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        head = f.read(8)
        if len(head) < 8:
            raise error(f"{name}: not a safetensors file ({size} bytes, less than its header length)")
        (length,) = struct.unpack("<Q", head)
        if length > MAX_HEADER_BYTES:
            raise error(f"{name}: a safetensors header of {length:,} bytes, more than {MAX_HEADER_BYTES:,}")
        if 8 + length > size:
            raise error(f"{name}: truncated: its header claims {length:,} bytes, the file has {size - 8:,}")
        text = f.read(length)
    header = parse_json(text, f"{name} (safetensors header)", max_depth=4, error=error)
    if not isinstance(header, dict):
        raise error(f"{name}: not a safetensors file (its header is not a JSON object)")
    metadata = header.pop("__metadata__", {})
    if not isinstance(metadata, dict) or not all(isinstance(v, str) for v in metadata.values()):
        raise error(f"{name}: __metadata__ is not a mapping of strings")
    if len(header) > MAX_TENSORS:
        raise error(f"{name}: declares {len(header):,} tensors, more than {MAX_TENSORS:,}")
    data_size = size - 8 - length
    entries = {key: _entry(name, key, value, error) for key, value in header.items()}
    ranges = sorted((e.begin, e.end, key) for key, e in entries.items())
    position = 0
    for begin, end, key in ranges:
        if begin != position:
            problem = "overlaps another" if begin < position else "leaves a gap before it"
            raise error(f"{name}: tensor {key!r}: its bytes {begin}-{end} {problem} (the data is tiled)")
        position = end
    if position != data_size:
        raise error(
            f"{name}: truncated or padded: its tensors hold {position:,} bytes, its data {data_size:,}"
        )
    return entries


def _entry(path: str, key: str, value: Any, error: type[Exception]) -> HeaderEntry:
    where = f"{path}: tensor {key!r}"
    if not isinstance(value, dict):
        raise error(f"{where}: not a tensor entry")
    dtype = SAFETENSORS_DTYPES.get(value.get("dtype"))  # type: ignore[arg-type]
    if dtype is None:
        raise error(f"{where}: dtype {value.get('dtype')!r} is not one of {', '.join(SAFETENSORS_DTYPES)}")
    shape, offsets = value.get("shape"), value.get("data_offsets")
    if not isinstance(shape, list) or len(shape) > 16 or not all(_count(n) for n in shape):
        raise error(f"{where}: shape {shape!r} is not a list of at most 16 non-negative integers")
    if not isinstance(offsets, list) or len(offsets) != 2 or not all(_count(n) for n in offsets):
        raise error(f"{where}: data_offsets {offsets!r} is not [begin, end]")
    begin, end = offsets
    expected = math.prod(shape) * dtype.itemsize
    if end - begin != expected:
        raise error(f"{where}: shape {tuple(shape)} of {value['dtype']} needs {expected:,} bytes, "
                    f"data_offsets give {end - begin:,}")  # fmt: skip
    return HeaderEntry(dtype, tuple(shape), begin, end)


def _count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def dtype_fits(stored: torch.dtype, expected: torch.dtype) -> bool:
    """Whether a tensor stored as ``stored`` may load into one of ``expected``: a floating tensor from any
    floating type (it is cast), any other only from its own type (a weight stored as integers or booleans,
    or a counter stored as a float, is refused rather than cast)."""
    return stored.is_floating_point if expected.is_floating_point else stored == expected


def check_header_fits(
    header: Mapping[str, HeaderEntry],
    expected: Mapping[str, torch.Tensor],
    source: str,
    owner: str,
    error: type[Exception] = ValueError,
) -> None:
    """Refuse a header whose tensors are not ``expected``'s (a ``meta`` state: names, shapes, dtypes).

    Types as :func:`dtype_fits`.
    """
    missing = [k for k in expected if k not in header]
    unexpected = [k for k in header if k not in expected]
    if missing or unexpected:
        what = f"lacks {missing[0]!r}" if missing else f"has {unexpected[0]!r}, which {owner} does not"
        raise error(f"{source}: does not fit {owner}: {what} "
                    f"({len(missing)} missing, {len(unexpected)} unexpected tensors)")  # fmt: skip
    for key, tensor in expected.items():
        entry = header[key]
        if entry.shape != tuple(tensor.shape):
            shape = tuple(tensor.shape)
            raise error(f"{source}: tensor {key!r} has shape {entry.shape}, {owner} expects {shape}")
        if not dtype_fits(entry.dtype, tensor.dtype):
            raise error(f"{source}: tensor {key!r} is stored as {entry.dtype}, {owner} holds {tensor.dtype} "
                        "(a weight of the wrong type is refused, not cast)")  # fmt: skip


def check_finite_weights(
    tensors: Mapping[str, torch.Tensor], source: str, error: type[Exception] = ValueError
) -> None:
    """Refuse the first floating tensor of ``tensors`` holding NaN or Inf (naming ``source`` and the key)."""
    for key, tensor in tensors.items():
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            bad = int((~torch.isfinite(tensor)).sum())
            count = tensor.numel()
            raise error(f"{source}: weights are not finite ({key}: {bad} of {count} values NaN or Inf)")


def total_values(state: Mapping[str, torch.Tensor]) -> int:
    """The number of values of a (``meta``) state dict."""
    return sum(t.numel() for t in state.values())
