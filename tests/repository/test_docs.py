"""The README and the documentation site say what the code does: the README stays a few screens with its
Python example running, the backbone guide's examples run, and the paper's numbers a tutorial quotes are those
the code prints. (``mkdocs build --strict`` in ``.ci/run`` checks the links and the API reference.)"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest
import torch

from skeleton_mamba.tasks.qean.module import QEAN_TABLE1

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```", re.M | re.S)


def _python_blocks(path: Path) -> list[str]:
    blocks = PYTHON_BLOCK.findall(path.read_text(encoding="utf-8"))
    assert blocks, f"{path} has no Python example"
    return blocks


def test_readme_is_a_few_screens_with_the_ci_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.encode()) <= 8 * 1024
    lines = text.splitlines()
    assert (
        'pip install torch==2.13.0 && pip install -e ".[dev]" && sm fit --recipe egodance_demo.yaml' in lines
    )
    assert "python -m pytest -q -n 2" in lines
    assert "![" in text and "docs/viewer.png" in text


def test_every_page_the_readme_links_exists():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert len(targets) > 10
    missing = [t for t in targets if not t.startswith("http") and not (ROOT / t).exists()]
    assert missing == []


@pytest.mark.parametrize("page", ["README.md", "docs/how-to/backbone.md"])
def test_python_examples_run(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the README's example writes my-backbone/
    torch.manual_seed(0)
    for block in _python_blocks(ROOT / page):
        namespace: dict = {}
        exec(compile(block, page, "exec"), namespace)
        for name, shape in [
            ("features", (2, 100, 25, 128)),
            ("x0_hat", (2, 150, 24, 9)),
            ("logits", (2, 60)),
        ]:
            if name in namespace:
                assert tuple(namespace[name].shape) == shape, (page, name)
                assert torch.isfinite(namespace[name]).all()
    if page == "README.md":
        from skeleton_mamba import SkeletonMamba

        loaded = SkeletonMamba.from_pretrained(tmp_path / "my-backbone")
        assert loaded.config.dim == 128 and loaded.config.depth == 8


def test_qean_tutorial_quotes_the_table_sm_test_prints():
    text = (DOCS / "tutorials" / "qean.md").read_text(encoding="utf-8")
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[0] in QEAN_TABLE1:
            rows[cells[0]] = (float(cells[1]), float(cells[2]) if cells[2] else None)
    assert rows == QEAN_TABLE1


def test_site_hook_unescapes_pipes_only_inside_table_code():
    spec = importlib.util.spec_from_file_location("table_pipes", DOCS / "hooks" / "table_pipes.py")
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    page = "| `--p a\\|b` | a \\| b `c\\|d` |\ntext `e\\|f`\n```\n| g\n```\n"
    assert hook.unescape_table_code(page) == "| `--p a|b` | a \\| b `c|d` |\ntext `e\\|f`\n```\n| g\n```\n"
