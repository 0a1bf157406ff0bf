"""Skeleton Mamba tasks (installed as ``skeleton_mamba.tasks``).

``motion`` is the shared motion and music toolkit; every other subpackage is one task with a pure
torch ``model.py``, a LightningModule ``module.py`` and a LightningDataModule ``data.py``.
"""
