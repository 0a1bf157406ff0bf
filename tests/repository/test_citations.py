"""Citations can be followed: every ``[Key]`` in the repository's text is defined in ``docs/references.md``,
and nothing cites documents that are not in the repository (the notes the code was first written from).

Scanned: ``.py`` (comments and string literals, so ``list[Path]`` or ``[None] * n`` in code are not
citations), ``.md`` (outside code blocks and inline code) and ``.yaml`` files, except virtual environments,
build folders and run outputs.
"""

from __future__ import annotations

import io
import os
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
REFERENCES = ROOT / "docs" / "references.md"
SKIP_DIRS = {
    ".git",
    ".venv",
    ".venv-ci",
    "build",
    "dist",
    "runs",
    "lightning_logs",
    "__pycache__",
    ".pytest_cache",
    ".ruff_cache",
    ".hypothesis",
    "node_modules",
}
SUFFIXES = {".py", ".md", ".yaml", ".yml"}

# Documents outside the repository. Written so that this file does not match itself.
UNFOLLOWABLE = [
    re.compile(r"\bseed\s+00[03]\b", re.I),  # the papers' file names in the working notes
    re.compile(r"\bseed(?:'s)?\s+(?:supplement|supplementary|table|eq\b|eqs\b|section|text\b)", re.I),
    re.compile(r"\b(?:dance|ssd_backbone|recognition_t2m|framework)\.md\b"),
    re.compile(r"\breference\s+§"),
    re.compile(r"\bseeds/READM[E]"),
]
# A citation key: an upper-case letter, first part at least two characters (so regex classes such as [A-Z]
# and one-letter placeholders are not keys), parts joined by a space or a hyphen: [NTU RGB+D], [Mamba-2].
CITATION = re.compile(r"(?<![\w\]\)\[`])\[([A-Z][A-Za-z0-9+]+(?:[ -][A-Za-z0-9+]+)*)\](?![(\[:\w])")
KEY_DEFINITION = re.compile(r"^- \*\*\[([^\]]+)\]\*\*", re.M)
FENCE = re.compile(r"^```.*?^```", re.M | re.S)
INLINE_CODE = re.compile(r"``.+?``|`[^`\n]+`")
CHANGELOG_HEADING = re.compile(r"^#+ \[[^\]]+\].*$", re.M)  # Keep a Changelog version headings


def repository_files() -> list[Path]:
    files = []
    for folder, dirs, names in os.walk(ROOT):
        dirs[:] = [d for d in dirs if d not in SKIP_DIRS and not d.endswith(".egg-info")]
        files += [Path(folder) / n for n in names if Path(n).suffix in SUFFIXES]
    return sorted(files)


def prose(path: Path, text: str) -> str:
    """The parts of a file that are prose: Python comments and strings, Markdown outside code, YAML."""
    if path.suffix == ".py":
        kinds = {tokenize.COMMENT, tokenize.STRING}
        kinds |= {getattr(tokenize, name) for name in ("FSTRING_MIDDLE",) if hasattr(tokenize, name)}
        tokens = tokenize.generate_tokens(io.StringIO(text).readline)
        text = "\n".join(tok.string for tok in tokens if tok.type in kinds)
    elif path.suffix == ".md":
        text = CHANGELOG_HEADING.sub("", FENCE.sub("", text))
    return INLINE_CODE.sub("", text)


def defined_keys() -> set[str]:
    return set(KEY_DEFINITION.findall(REFERENCES.read_text(encoding="utf-8")))


def test_references_define_the_keys_the_brief_names():
    keys = defined_keys()
    named = ["EgoMusic", "QEAN", "Mamba-2", "EDGE", "FACT", "Bailando", "MDM", "PYSKL", "HumanML3D", "T2M"]
    named += ["DDPM", "DDIM", "EDM", "SMPL", "AIST++", "NTU RGB+D", "Kinetics", "ST-GCN", "GMD", "PhysDiff"]
    for key in named:
        assert key in keys, f"docs/references.md does not define [{key}]"


def test_scanner_finds_citations_and_ignores_code():
    code = 'x: list[Path] = [None] * 3  # [EgoMusic] supp. Eq. 15\ns = "[QEAN] Table 1"\nr = r"[A-Z]"\n'
    found = CITATION.findall(prose(Path("m.py"), code))
    assert found == ["EgoMusic", "QEAN"]
    md = "## [Unreleased]\n[a link](x) and [NTU RGB+D] and `[Inline]`\n```\n[Fenced]\n```\n"
    assert CITATION.findall(prose(Path("m.md"), md)) == ["NTU RGB+D"]
    assert UNFOLLOWABLE[0].search("as in " + "seed 0" + "03 Table 1")
    assert not any(p.search("the 120-frame seed motion; a random seed") for p in UNFOLLOWABLE)


def test_no_citation_of_documents_outside_the_repository():
    bad = []
    for path in repository_files():
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if any(p.search(line) for p in UNFOLLOWABLE):
                bad.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not bad, "cite the paper by key (docs/references.md), not the working notes:\n" + "\n".join(bad)


def test_every_citation_key_is_defined():
    keys = defined_keys()
    bad = []
    for path in repository_files():
        if path == Path(__file__).resolve():  # its examples of what is and is not a citation
            continue
        try:
            text = prose(path, path.read_text(encoding="utf-8"))
        except (tokenize.TokenError, SyntaxError) as err:  # pragma: no cover - the repository's files parse
            pytest.fail(f"{path}: {err}")
        bad += [f"{path.relative_to(ROOT)}: [{key}]" for key in CITATION.findall(text) if key not in keys]
    assert not bad, "citation keys not defined in docs/references.md:\n" + "\n".join(sorted(set(bad)))
