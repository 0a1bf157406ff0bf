"""Atomic file writes for the toolkit: :mod:`skeleton_mamba.atomic` (the backbone's ``save_pretrained`` writes
through it too, so every writer of the project shares one implementation and one file mode)."""

from skeleton_mamba.atomic import atomic_open, atomic_path, check_writable

__all__ = ["atomic_open", "atomic_path", "check_writable"]
