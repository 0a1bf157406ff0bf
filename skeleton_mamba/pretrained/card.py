"""The model card (``README.md``) of a pretrained folder: Hub front matter, the network, its training, data,
metrics and the BibTeX of the papers it cites.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import torch

from skeleton_mamba.config import SkeletonMambaConfig
from skeleton_mamba.pretrained.codec import class_name, encode_value

__all__ = ["CITATIONS", "model_card"]

# BibTeX of the papers a card cites, by the keys of the project's docs/references.md.
CITATIONS: dict[str, str] = {
    "EgoMusic": """@inproceedings{nguyen2025egomusic,
  title = {EgoMusic-driven Human Dance Motion Estimation with Skeleton Mamba},
  author = {Nguyen, Q. and Le, N. and Huang, B. and others},
  booktitle = {ICCV},
  year = {2025},
  eprint = {2508.10522},
  archivePrefix = {arXiv}
}""",
    "Mamba-2": """@inproceedings{dao2024transformers,
  title = {Transformers are {SSMs}: Generalized Models and Efficient Algorithms Through Structured State
           Space Duality},
  author = {Dao, Tri and Gu, Albert},
  booktitle = {ICML},
  year = {2024},
  eprint = {2405.21060},
  archivePrefix = {arXiv}
}""",
    "QEAN": """@article{zhou2024qean,
  title = {{QEAN}: Quaternion-Enhanced Attention Network for Visual Dance Generation},
  author = {Zhou, Z. and Huo, Y. and Huang, G. and others},
  journal = {arXiv preprint arXiv:2403.11626},
  year = {2024}
}""",
    "EDGE": """@inproceedings{tseng2023edge,
  title = {{EDGE}: Editable Dance Generation From Music},
  author = {Tseng, Jonathan and Castellon, Rodrigo and Liu, C. Karen},
  booktitle = {CVPR},
  year = {2023},
  eprint = {2211.10658},
  archivePrefix = {arXiv}
}""",
    "MDM": """@inproceedings{tevet2023mdm,
  title = {Human Motion Diffusion Model},
  author = {Tevet, G. and Raab, S. and Gordon, B. and others},
  booktitle = {ICLR},
  year = {2023},
  eprint = {2209.14916},
  archivePrefix = {arXiv}
}""",
    "PYSKL": """@inproceedings{duan2022pyskl,
  title = {{PYSKL}: Towards Good Practices for Skeleton Action Recognition},
  author = {Duan, Haodong and Wang, Jiaqi and Chen, Kai and Lin, Dahua},
  booktitle = {ACM Multimedia},
  year = {2022},
  eprint = {2205.09443},
  archivePrefix = {arXiv}
}""",
}


def _backbone_config(model: torch.nn.Module) -> SkeletonMambaConfig | None:
    for module in model.modules():
        config = getattr(module, "config", None)
        if isinstance(config, SkeletonMambaConfig):
            return config
    return None


def _table(rows: Mapping[str, Any]) -> list[str]:
    return ["| | |", "| --- | --- |", *(f"| {k} | {v} |" for k, v in rows.items())]


def model_card(model: torch.nn.Module, info: Mapping[str, Any] | None = None) -> str:
    """The README.md of a folder: Hub front matter, task, skeleton and sizes, recipe, data, metrics, citation.

    ``info`` (all optional): ``task``, ``recipe``, ``module`` (class path), ``hparams`` (the module's),
    ``data`` (class path), ``data_hparams``, ``metrics`` ({name: value} of a test run), ``trained``
    ({"epoch": .., "global_step": ..}).

    Examples:
        >>> from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
        >>> model = SkeletonMamba(SkeletonMambaConfig(dim=32, depth=1, mlp_dim=16))
        >>> card = model_card(model, {"metrics": {"MPJPE": 0.07}})
        >>> card.splitlines()[:3], "| MPJPE | 0.07 |" in card, "[Mamba-2]" in card
        (['---', 'library_name: skeleton-mamba', 'license: apache-2.0'], True, True)
    """
    info = dict(info or {})
    cls = type(model)
    keys = list(dict.fromkeys([*info.get("citations", ()), *getattr(cls, "pretrained_citations", ())]))
    backbone = _backbone_config(model)
    params = sum(p.numel() for p in model.parameters())
    task = info.get("task") or getattr(cls, "pretrained_task", "")
    tags = ["skeleton-mamba", "mamba2", "human-motion", "pytorch"]
    lines = ["---", "library_name: skeleton-mamba", "license: apache-2.0", "tags:", *(f"- {t}" for t in tags)]
    lines += ["---", "", f"# {cls.__name__}", ""]
    if task:
        lines += [f"{task}", ""]
    sizes: dict[str, Any] = {"class": f"`{class_name(cls)}`", "parameters": f"{params:,}"}
    if backbone is not None:
        mixer = backbone.mixer
        sizes.update(
            skeleton=f"`{backbone.skeleton}`",
            **{"width D": backbone.dim, "blocks N": backbone.depth, "MLP width": backbone.mlp_dim},
            **{"temporal scan": "causal (streams frame by frame)" if backbone.causal else "bidirectional"},
            **{
                "cross-attention context": backbone.context_dim
                if backbone.context_dim is not None
                else "none"
            },
        )
        if mixer is not None:
            sizes.update({"SSD state N / head width": f"{mixer.d_state} / {mixer.headdim}"})
    lines += ["## Network", "", *_table(sizes), ""]
    if info.get("recipe") or info.get("module") or info.get("hparams"):
        lines += ["## Training", ""]
        if info.get("recipe"):
            lines += [f"Recipe: `{info['recipe']}`.", ""]
        if info.get("module"):
            lines += [f"Lightning module: `{info['module']}`.", ""]
        if info.get("trained"):
            lines += [", ".join(f"{k} {v}" for k, v in info["trained"].items()) + ".", ""]
        if info.get("hparams"):
            lines += [
                "Hyper-parameters:",
                "",
                "```json",
                json.dumps(encode_value(info["hparams"], "hparams"), indent=2),
                "```",
                "",
            ]
    if info.get("data") or info.get("data_hparams"):
        lines += ["## Data", ""]
        if info.get("data"):
            lines += [f"Data module: `{info['data']}`.", ""]
        if info.get("data_hparams"):
            lines += [
                "```json",
                json.dumps(encode_value(info["data_hparams"], "data_hparams"), indent=2),
                "```",
                "",
            ]
    lines += ["## Metrics", ""]
    metrics = info.get("metrics")
    if metrics:
        lines += ["| metric | value |", "| --- | --- |", *(f"| {k} | {v} |" for k, v in metrics.items()), ""]
    else:
        lines += ["No test was run for this folder.", ""]
    lines += [
        "## Use",
        "",
        "```python",
        f"from {cls.__module__} import {cls.__name__}",
        "",
        f'model = {cls.__name__}.from_pretrained("path/or/org-name")  # safetensors only, eval mode',
        "```",
        "",
    ]
    if keys:
        cited = ", ".join(f"[{k}]" for k in keys)
        lines += [
            "## Citation",
            "",
            f"Papers, by the keys of the project's `docs/references.md`: {cited}.",
            "",
        ]
        lines += ["```bibtex", *(CITATIONS[k] for k in keys if k in CITATIONS), "```", ""]
    return "\n".join(lines)
