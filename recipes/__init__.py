"""Packaged YAML recipes (installed as ``skeleton_mamba.recipes``); ``sm recipes`` lists them."""
