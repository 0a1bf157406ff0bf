"""Every public name of the backbone has a short example in its docstring, and every example runs.

The examples are doctests (``>>>``); this module runs them with :mod:`doctest` so the README's test command
checks them (``python -m pytest --doctest-modules skeleton_mamba`` runs the same examples).
"""

from __future__ import annotations

import doctest
import importlib

import pytest

import skeleton_mamba

API = skeleton_mamba._API  # public name -> the module that defines it
MODULES = sorted(set(API.values()) | {"skeleton_mamba.allocator"})


@pytest.mark.parametrize("module_name", MODULES)
def test_the_examples_of_each_backbone_module_run(module_name):
    module = importlib.import_module(module_name)
    if module_name == "skeleton_mamba.ssd":  # the package re-exports; its examples live in dispatch
        module = importlib.import_module("skeleton_mamba.ssd.dispatch")
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.attempted > 0, f"{module_name} has no example"
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {module_name} failed"


@pytest.mark.parametrize("name", sorted(API))
def test_every_public_name_has_an_example(name):
    module = importlib.import_module(API[name])
    if name == "ssd":
        module = importlib.import_module("skeleton_mamba.ssd.dispatch")
    examples = [t for t in doctest.DocTestFinder().find(module) if t.examples]
    assert any(name in example.source for t in examples for example in t.examples), (
        f"{name}: no example in {module.__name__} uses it"
    )
