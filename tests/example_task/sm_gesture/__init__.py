"""Gesture: an example Skeleton Mamba task in its own distribution (2-D keypoints -> gesture class).

``task.py`` is its registration (the entry point ``gesture`` of ``skeleton_mamba.tasks``), ``model.py`` the
pure-torch network, ``module.py`` the LightningModule, ``data.py`` the data module on generated keypoints,
``onnx_graphs.py`` the network's ONNX graph and ``gesture_demo.yaml`` its recipe.
"""
