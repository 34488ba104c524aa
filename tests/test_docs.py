"""The README is a short user's guide that opens with the two set-up commands CI runs; docs/ holds the rest, and no
link in either points nowhere."""
from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
DOCS = ROOT / "docs"
PAGES = ("design", "tasks", "motion", "collision", "sessions", "benchmarks")  # the pages the README must send readers to
FAST_SUBSET = 'python3 -m pytest -q -n 2 -m "not slow and not browser"'
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```[a-z]*\n(.*?)^```", re.S | re.M)


def _opening() -> str:
    """The README up to its first section heading."""
    text = README.read_text()
    return text[:text.index("\n## ")]


def _ci_commands() -> list[str]:
    """The install and test commands of .ci/run, in order."""
    lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    return [line for line in lines if line.startswith(("apt-get ", "python3 -m pip install", "python3 -m pytest"))]


def _slug(heading: str) -> str:
    """GitHub's anchor of a markdown heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_readme_is_a_short_guide():
    size = README.stat().st_size
    assert size <= 12_000, f"README.md is {size:,} bytes; move details to docs/ (at most 12,000)"


def test_readme_opens_with_the_two_set_up_commands():
    """First the install and start of the workbench, then exactly what CI installs and runs (pip for `python3 -m pip`)."""
    blocks = [b.strip() for b in FENCE.findall(_opening())]
    assert len(blocks) >= 2, blocks
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "regrasp" in project["scripts"]
    assert blocks[0] == "pip install -e . && regrasp workbench"
    assert project["requires-python"] == ">=3.11" and "Python 3.11" in _opening()
    ci = [c.removeprefix("python3 -m ") if c.startswith("python3 -m pip") else c for c in _ci_commands()]
    assert blocks[1] == " && ".join(ci), f"the README's test command must be .ci/run's: {' && '.join(ci)}"
    assert "pip install -e '.[test]'" in ci and "test" in project["optional-dependencies"]


def test_readme_documents_the_fast_subset():
    text = README.read_text()
    assert FAST_SUBSET in text
    markers = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]["markers"]
    assert {m.split(":")[0] for m in markers} >= {"slow", "browser"}


def test_readme_links_every_docs_page():
    linked = {(README.parent / target.split("#")[0]).resolve() for target in LINK.findall(README.read_text())}
    pages = {p.resolve() for p in DOCS.glob("*.md")} | {(DOCS / f"{name}.md").resolve() for name in PAGES}
    missing = sorted(p.name for p in pages - linked)
    assert missing == [], f"README.md links no docs page {missing}"


def test_every_relative_link_resolves():
    """Every relative link of README.md and docs/*.md names an existing file, and an anchor a heading of it."""
    broken = []
    for page in [README, *sorted(DOCS.glob("*.md"))]:
        for target in LINK.findall(page.read_text()):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, anchor = target.partition("#")
            file = (page.parent / path).resolve() if path else page
            if not file.is_file():
                broken.append(f"{page.name}: {target}")
            elif anchor and anchor not in {_slug(h) for h in re.findall(r"^#+ (.*)$", file.read_text(), re.M)}:
                broken.append(f"{page.name}: {target} (no such heading)")
    assert broken == []


def _reader_keys() -> set[str]:
    """Every key the TOML readers accept: the constant names in the `check_keys({...})` calls of planner/, and the
    parameters of the generated shapes (`Shape(make, {...})`)."""
    keys = set()
    for path in (ROOT / "planner").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Call) or not node.args:
                continue
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            if name == "check_keys" and isinstance(node.args[0], ast.Set):
                keys |= {e.value for e in node.args[0].elts if isinstance(e, ast.Constant)}
            elif name == "Shape" and len(node.args) > 1 and isinstance(node.args[1], ast.Dict):
                keys |= {k.value for k in node.args[1].keys if isinstance(k, ast.Constant)}
    return keys


def test_the_toml_reference_names_every_key():
    keys = _reader_keys()
    assert {"robot", "tip_radius", "plan_seed", "major_radius"} <= keys, "the readers' keys were not found"
    text = (DOCS / "tasks.md").read_text()
    missing = sorted(k for k in keys if f"`{k}`" not in text)
    assert missing == [], f"docs/tasks.md does not document {missing}"
