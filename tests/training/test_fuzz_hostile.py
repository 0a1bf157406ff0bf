"""Hostile recipes (issue 33): alias / merge-key bombs, deep nesting and huge files are refused on one line.

The bounds of :mod:`skeleton_mamba.tasks.training.recipe_resolution` are checked against expanded sizes
counted by hand; the real ``sm fit`` runs under an address-space limit (``RLIMIT_AS``) so that a bomb that
got through would fail the test by running out of memory rather than pass after a long time.
"""

from __future__ import annotations

import resource
import subprocess

import pytest

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.training import recipe_resolution
from skeleton_mamba.tasks.training.recipe_resolution import bounded_yaml_load, check_yaml_bounds
from tests.helpers.sm import sm_executable

MEMORY_LIMIT = 3 << 30  # bytes of address space for the `sm` subprocess (a bomb would need tens of GB)


def _billion_laughs(levels: int = 9, width: int = 10) -> str:
    lines = [f"a0: &a0 [{', '.join(['lol'] * width)}]"]
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]")
    return "\n".join(lines) + "\n"


def _merge_bomb(levels: int = 8, width: int = 10) -> str:
    lines = [f"m0: &m0 {{{', '.join(f'k{j}: {j}' for j in range(width))}}}"]
    for i in range(1, levels):
        lines.append(f"m{i}: &m{i} {{<<: *m{i - 1}, {', '.join(f'c{j}: *m{i - 1}' for j in range(width))}}}")
    return "\n".join(lines) + "\n"


def test_flat_list_is_counted_as_its_scalars_plus_key_sequence_and_root(monkeypatch):
    # {"x": [1] * n}: n scalars + the sequence + the key "x" + the root mapping = n + 3 nodes
    text = "x: [" + ", ".join(["1"] * 20) + "]\n"
    monkeypatch.setattr(recipe_resolution, "MAX_RECIPE_NODES", 23)
    assert bounded_yaml_load(text) == {"x": [1] * 20}
    monkeypatch.setattr(recipe_resolution, "MAX_RECIPE_NODES", 22)
    with pytest.raises(InputError, match="aliases are expanded"):
        check_yaml_bounds(text)


def test_aliases_are_counted_expanded(monkeypatch):
    # root 1 + key a 1 + [x, x] 3 + key b 1 + [*a, *a, *a] (1 + 3 * 3) = 16 nodes once expanded
    text = "a: &a [x, x]\nb: [*a, *a, *a]\n"
    monkeypatch.setattr(recipe_resolution, "MAX_RECIPE_NODES", 16)
    check_yaml_bounds(text)
    monkeypatch.setattr(recipe_resolution, "MAX_RECIPE_NODES", 15)
    with pytest.raises(InputError, match=r"recipe\.yaml:1: more than 15 values"):
        check_yaml_bounds(text, "recipe.yaml")


def test_depth_is_bounded_with_the_line(monkeypatch):
    text = "a:\n  b:\n    c: [[1]]\n"  # mapping, mapping, mapping, sequence, sequence: 5 levels
    monkeypatch.setattr(recipe_resolution, "MAX_RECIPE_DEPTH", 5)
    check_yaml_bounds(text)
    monkeypatch.setattr(recipe_resolution, "MAX_RECIPE_DEPTH", 4)
    with pytest.raises(InputError, match=r"r\.yaml:3: nested more than 4 levels deep"):
        check_yaml_bounds(text, "r.yaml")


def test_size_is_bounded(monkeypatch):
    monkeypatch.setattr(recipe_resolution, "MAX_RECIPE_BYTES", 10)
    check_yaml_bounds("a: 1234567")  # 10 bytes
    with pytest.raises(InputError, match="11 bytes, more than a recipe's 10"):
        check_yaml_bounds("a: 12345678")


def test_packaged_recipes_fit_the_bounds():
    for name, path in recipe_resolution.packaged_recipes().items():
        check_yaml_bounds(path.read_text(encoding="utf-8"), name)


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


HOSTILE_RECIPES = {
    "billion_laughs": (_billion_laughs(), "aliases are expanded"),
    "merge_bomb": (_merge_bomb(), "aliases are expanded"),
    "deep_sequences": ("x: " + "[" * 5000 + "]" * 5000 + "\n", "nested more than"),
    "deep_mappings": ("x: " + "{a: " * 5000 + "1" + "}" * 5000 + "\n", "nested more than"),
    "callbacks_bomb": (
        _billion_laughs() + "trainer:\n  callbacks: *a8\n",
        "aliases are expanded",
    ),
}


@pytest.mark.parametrize("inline", [False, True], ids=["file", "inline"])
@pytest.mark.parametrize("case", sorted(HOSTILE_RECIPES))
def test_sm_fit_refuses_hostile_recipes_on_one_line(tmp_path, case, inline):
    text, expected = HOSTILE_RECIPES[case]
    path = tmp_path / f"{case}.yaml"
    path.write_text(text, encoding="utf-8")
    work = tmp_path / "work"
    work.mkdir()
    args = ["--recipe", "recognition_synthetic.yaml", "--config", text] if inline else ["--recipe", str(path)]
    proc = subprocess.run(
        [sm_executable(), "fit", *args],
        cwd=work,
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_limit_memory,
    )
    err_lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert len(err_lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert expected in err_lines[0]
    assert (str(path) if not inline else "--config inline YAML") in err_lines[0]
    assert list(work.iterdir()) == []  # nothing written
