"""Package discovery for the namespaced layout (all metadata lives in pyproject.toml).

The repository keeps ``tasks/`` and ``recipes/`` at the top level for readability, but they are
installed as ``skeleton_mamba.tasks`` and ``skeleton_mamba.recipes`` so the distribution never
claims generic top-level names. setuptools resolves every subpackage through the
``package_dir`` prefix mapping, for wheels and for editable installs alike.
"""

from setuptools import find_packages, setup

MAPPED = {"skeleton_mamba.tasks": "tasks", "skeleton_mamba.recipes": "recipes"}

packages = find_packages(include=["skeleton_mamba", "skeleton_mamba.*"])
for name, folder in MAPPED.items():
    packages += [name] + [f"{name}.{sub}" for sub in find_packages(folder)]

setup(packages=packages, package_dir=MAPPED)
