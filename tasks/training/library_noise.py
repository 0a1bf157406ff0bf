"""What the libraries print that a user of ``sm`` cannot act on, silenced at its source by its exact text.

Two kinds: warnings a library raises about its own use of another library's API (ignored through
``warnings.filterwarnings`` with the message, category and module), and log lines a library writes on every
run (dropped by a :class:`logging.Filter` on the library's own logger, matching the message). Each entry
names the versions it was seen with; every other warning and log line still shows. ``sm`` applies them
before it imports a command (:func:`silence_library_noise`): a filter set on a logger's name holds for the
logger the library creates later.
"""

from __future__ import annotations

import logging
import re
import warnings

__all__ = ["LIBRARY_LOG_LINES", "LIBRARY_WARNINGS", "silence_library_noise"]

_LEAF_SPEC = r"`isinstance\(treespec, LeafSpec\)` is deprecated"

# (message, category, module) as for warnings.filterwarnings
LIBRARY_WARNINGS: tuple[tuple[str, type[Warning], str], ...] = (
    # lightning 2.6.6 (utilities/_pytree.py) with torch 2.13, on every fit
    (_LEAF_SPEC, FutureWarning, r"lightning\.pytorch\.utilities\._pytree"),
    # torch 2.13's torch.export deep-copies its own LeafSpec (the warning points at copyreg), sm export-onnx
    (_LEAF_SPEC, FutureWarning, r"copyreg"),
)

# (logger name, message): a record of that logger whose message matches (at its start) is dropped
_RANK_ZERO = ("lightning.pytorch.utilities.rank_zero", "lightning.fabric.utilities.rank_zero")
LIBRARY_LOG_LINES: tuple[tuple[str, str], ...] = (
    # lightning 2.6.6: adverts through rank_zero_info (whose logger is the rank_zero module's of
    # lightning.pytorch or of fabric): for LitLogger on every Trainer without one (logger_connector), for
    # litmodels on a Trainer without a ModelCheckpoint (callback_connector)
    *((name, r"💡 Tip: For seamless cloud (logging|uploads)") for name in _RANK_ZERO),
    # torch 2.13's ONNX exporter, 4 lines per graph (torchvision's detection ops, which no network here uses)
    ("torch.onnx._internal.exporter._registration", r"torchvision is not installed\. Skipping torchvision::"),
)


class _DropMatching(logging.Filter):
    """Drops the records whose message matches ``pattern`` (at its start)."""

    def __init__(self, pattern: str) -> None:
        super().__init__()
        self.pattern = re.compile(pattern)

    def filter(self, record: logging.LogRecord) -> bool:
        return self.pattern.match(record.getMessage()) is None


def silence_library_noise() -> None:
    """Ignore :data:`LIBRARY_WARNINGS` and drop :data:`LIBRARY_LOG_LINES` (only those); repeatable."""
    for message, category, module in LIBRARY_WARNINGS:
        warnings.filterwarnings("ignore", message=message, category=category, module=module)
    for name, pattern in LIBRARY_LOG_LINES:
        logger = logging.getLogger(name)
        if not any(isinstance(f, _DropMatching) and f.pattern.pattern == pattern for f in logger.filters):
            logger.addFilter(_DropMatching(pattern))
