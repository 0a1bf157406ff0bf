"""AIST++ split name lists (package data read by ``skeleton_mamba.tasks.motion.formats.aistpp``)."""
