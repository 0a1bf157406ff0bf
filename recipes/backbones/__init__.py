"""Backbone fragments that task recipes include (``backbone: backbones/skeleton_mamba.yaml``)."""
