"""Journey (e): a trained model -> ``sm export-pretrained`` -> ``from_pretrained`` in Python ->
``sm export-onnx --pretrained`` -> onnxruntime; and a fresh backbone from the packaged fragments by the
names recipes use (``--backbone backbones/skeleton_mamba_tiny.yaml``), from a folder without ``recipes/``
(a pip user's)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import yaml

from skeleton_mamba.tasks.recognition.model import ActionRecognizer
from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule
from skeleton_mamba.tasks.training.cli import main as sm_main
from skeleton_mamba.tasks.training.onnx_export import backbone_from_yaml
from skeleton_mamba.tasks.training.recipe_resolution import packaged_recipe_dir
from tests.helpers.checkpoint_files import save_module_checkpoint

ort = pytest.importorskip("onnxruntime", reason="onnxruntime runs the exported graphs")


def test_checkpoint_to_pretrained_to_onnx(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    torch.manual_seed(0)
    backbone = {"dim": 16, "depth": 1, "heads": 2, "mlp_dim": 32, "causal": True,
                "mixer": {"d_state": 8, "headdim": 8, "chunk_size": 16}}  # fmt: skip
    module = ActionRecognitionModule(backbone=backbone, num_classes=4)
    module.hparams["_class_path"] = f"{module.__module__}.ActionRecognitionModule"  # as sm fit writes
    ckpt = save_module_checkpoint(module, tmp_path / "last.ckpt")

    assert sm_main(["export-pretrained", "--ckpt", str(ckpt), "--out", "rec-pretrained"]) == 0
    loaded = ActionRecognizer.from_pretrained(tmp_path / "rec-pretrained").eval()
    x = torch.randn(1, 2, 12, 25, 3)  # (batch, bodies, frames, joints, xyz)
    with torch.no_grad():
        expected = module.model.eval()(x)
        torch.testing.assert_close(loaded(x), expected)

    assert sm_main(["export-onnx", "--pretrained", "rec-pretrained", "--out", "onnx", "--check"]) == 0
    printed = capsys.readouterr().out
    assert "wrote sequence.onnx" in printed and "onnxruntime vs eager" in printed
    record = json.loads((tmp_path / "onnx" / "export.json").read_text())
    assert record["network"] == "ActionRecognizer" and record["skeleton"] == "ntu25"
    session = ort.InferenceSession(str(tmp_path / "onnx" / "sequence.onnx"))
    names = [i.name for i in session.get_inputs()]
    feed = {names[0]: x.numpy()}
    if len(names) > 1:  # a padding mask: every frame valid
        feed[names[1]] = np.ones((1, 12), dtype=bool)
    (logits,) = session.run(None, feed)
    np.testing.assert_allclose(logits, expected.numpy(), atol=1e-4, rtol=0)


def _export_backbone(name: str, *extra: str) -> int:
    args = ["export-onnx", "--backbone", name, "--skeleton", "ntu25", "--in-channels", "3", *extra]
    return sm_main([*args, "--out", "onnx", "--frames", "4"])


@pytest.mark.parametrize("name", ["backbones/skeleton_mamba_tiny.yaml", "skeleton_mamba_tiny"])
def test_packaged_backbone_names_resolve_anywhere(tmp_path, monkeypatch, capsys, name):
    monkeypatch.chdir(tmp_path)  # no recipes/ folder here
    fields = yaml.safe_load((packaged_recipe_dir() / "backbones" / "skeleton_mamba_tiny.yaml").read_text())
    built = backbone_from_yaml(name, {"skeleton": "ntu25", "in_channels": 3, "causal": None})
    assert all(getattr(built.config, key) == value for key, value in fields.items() if key != "mixer")
    assert built.config.skeleton == "ntu25" and built.config.in_channels == 3
    assert sm_main(["export-onnx", "--backbone", "backbones/nope.yaml", "--out", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "backbones/nope.yaml: no such backbone file" in err[0]
    assert "skeleton_mamba_tiny" in err[0] and not (tmp_path / "x").exists()


@pytest.mark.slow
def test_a_packaged_causal_backbone_exported_by_its_recipe_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["export-onnx", "--backbone", "backbones/skeleton_mamba_tiny.yaml", "--skeleton", "ntu25"]
    assert sm_main([*args, "--in-channels=3", "--causal", "--check", "--out=onnx", "--frames=4"]) == 0
    assert (tmp_path / "onnx" / "sequence.onnx").stat().st_size > 0
    assert (tmp_path / "onnx" / "step.onnx").stat().st_size > 0
