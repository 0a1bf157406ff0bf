"""Structured state-space duality (SSD, Mamba-2): recurrence, chunked and quadratic forms, kernel."""

from skeleton_mamba.ssd.chunked import ssd_chunked
from skeleton_mamba.ssd.dispatch import ssd
from skeleton_mamba.ssd.quadratic import ssd_quadratic
from skeleton_mamba.ssd.recurrence import ssd_recurrence

__all__ = ["ssd", "ssd_chunked", "ssd_quadratic", "ssd_recurrence"]
