"""The README and the documentation pages: short, their links resolve, the tour runs.

The docs site itself is built (tutorials executed, warnings as errors) by ``.ci/run`` after the
test suite; these checks are the fast part a plain ``pytest`` runs.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
DOCS = ROOT / "docs"

_LINK = re.compile(r"\]\(([^)\s]+)\)")


def broken_links(path: Path) -> list[str]:
    """Relative links of a Markdown file that name no file or folder (anchors dropped)."""
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    bad = []
    for target in _LINK.findall(text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        if not (path.parent / target.split("#")[0]).exists():
            bad.append(target)
    return bad


def test_readme_is_short():
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 200


def test_readme_test_command_is_the_ci_command():
    ci = (ROOT / ".ci" / "run").read_text()
    cmd = 'python -m pip install -e ".[test]" && python -m pytest'
    assert cmd in README.read_text(encoding="utf-8") and cmd in ci


@pytest.mark.parametrize("page", [README, *sorted(DOCS.rglob("*.md"))], ids=lambda p: str(p.relative_to(ROOT)))
def test_links_resolve(page):
    if "_build" in page.parts or "auto_tutorials" in page.parts:
        pytest.skip("build output")
    assert broken_links(page) == []


def test_link_check_catches_a_broken_link(tmp_path):
    # negative control: the same checker on a page with a link to nothing
    page = tmp_path / "page.md"
    page.write_text("see [here](nowhere/missing.md) and [ok](page.md#top), [web](https://example.org)\n")
    assert broken_links(page) == ["nowhere/missing.md"]


def test_every_page_is_in_a_toctree():
    # Sphinx warns (an error under -W) about orphans only when the docs are built; say it here too.
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"^([a-z_/-]+)$", index, flags=re.M))
    pages = {p.relative_to(DOCS).with_suffix("").as_posix() for p in DOCS.rglob("*.md")
             if "_build" not in p.parts and "auto_tutorials" not in p.parts} - {"index"}
    pages |= {p.relative_to(DOCS).with_suffix("").as_posix() for p in (DOCS / "reference").glob("*.rst")}
    assert pages <= listed, sorted(pages - listed)


def test_readme_tour_runs(tmp_path):
    """The README's Python tour, pasted into a fresh interpreter, runs and prints what it says."""
    code = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)[0]
    env = {**os.environ, "METHODGEN_CACHE": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    lines = r.stdout.splitlines()
    assert lines[0] == "('H', 'Lx', 'Ly', 'Lz')" and lines[1] == "ok"
    assert lines[2].startswith("reached t = 10.0")
    assert abs(float(lines[2].split()[-1])) < 1e-14   # H kept to round-off
