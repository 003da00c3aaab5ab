"""The docs a user reads point at nothing outside the repository, and cite each rig's source."""

import re
from pathlib import Path

import robocal

ROOT = Path(__file__).resolve().parents[1]
SRC = Path(robocal.__file__).parent
#: Paths of the project's private working folders: they do not exist in a user's clone.
OUTSIDE = re.compile(r"shared/(seeds|spec)|\.\./shared\b|spec 0\d-")


def _user_facing():
    yield ROOT / "README.md"
    yield from sorted((ROOT / "docs").rglob("*.md"))
    yield from sorted(SRC.rglob("*.py"))
    yield from sorted(SRC.rglob("*.urdf"))


def test_no_path_outside_the_repository():
    hits = [f"{p.relative_to(ROOT)}:{i}: {line.strip()[:80]}"
            for p in _user_facing() for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
            if OUTSIDE.search(line)]
    assert not hits, hits


def test_sources_page_gives_each_rig_a_bibliographic_reference():
    text = (ROOT / "docs" / "sources.md").read_text(encoding="utf-8")
    for sid in ("s0", "s1", "s2", "s3", "s4"):
        assert f'<a id="{sid}"></a>' in text, sid
    # the identifiers a reader can look up
    assert "CN 101096101" in text and "10.13873/J.1000-9787(2017)10-0061-03" in text
