"""``sm dance --list-samples``: the held-out sample folders of a checkpoint's data, for ``--sample``."""

from __future__ import annotations

import json

import pytest
import torch

from skeleton_mamba.tasks.egodance.data import EgoDanceDataModule
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.checkpoint_files import save_module_checkpoint


def _fake_build(root, sources: list[str]) -> list:
    """Sample folders with a COMPLETE marker and the motion source in meta.json (two windows per source)."""
    folders = []
    for i, source in enumerate(s for s in sources for _ in range(2)):
        folder = root / "samples" / f"{source}_w{i:03d}"
        folder.mkdir(parents=True)
        (folder / "meta.json").write_text(json.dumps({"motion": {"source": source}}), encoding="utf-8")
        (folder / "COMPLETE").write_text("ok\n", encoding="utf-8")
        folders.append(folder)
    return folders


def test_list_samples_prints_the_held_out_folders_only(tmp_path, tiny_egodance_module, capsys):
    root = tmp_path / "ego"
    folders = _fake_build(root, [f"dancer{k:02d}" for k in range(10)])
    module = tiny_egodance_module()
    data = {"root": str(root), "val_fraction": 0.2, "test_fraction": 0.2, "window": 150}
    ckpt = tmp_path / "emm.ckpt"
    save_module_checkpoint(module, ckpt, datamodule_hyper_parameters=data)
    assert sm_main(["dance", "--ckpt", str(ckpt), "--list-samples"]) == 0
    out = capsys.readouterr().out.splitlines()
    listed = {line for line in out if not line.startswith("#")}
    headers = [line for line in out if line.startswith("#")]
    assert [h.split(":")[0] for h in headers] == ["# test", "# val"]
    assert all("--sample FOLDER" in h for h in headers)
    train = set(
        map(str, EgoDanceDataModule(str(root), val_fraction=0.2, test_fraction=0.2).split_folders()["train"])
    )
    assert listed and not listed & train and listed | train == set(map(str, folders))

    def source(path: str) -> str:
        return path.rsplit("/", 1)[1].split("_w")[0]

    assert not {source(p) for p in listed} & {source(p) for p in train}  # no source straddles

    # no --out needed to list; still needed to dance
    (tmp_path / "x.wav").write_bytes(b"")  # an input that exists: --music is checked before --out
    with pytest.raises(SystemExit):
        sm_main(["dance", "--ckpt", str(ckpt), "--music", str(tmp_path / "x.wav")])
    assert "required: --out" in capsys.readouterr().err

    # a checkpoint without data hyper-parameters: one line, exit 2
    torch.save(
        {k: v for k, v in torch.load(ckpt, weights_only=True).items() if k != "datamodule_hyper_parameters"},
        ckpt,
    )
    assert sm_main(["dance", "--ckpt", str(ckpt), "--list-samples"]) == 2
    assert "holds no data module hyper-parameters" in capsys.readouterr().err
