"""The README is the short tour (issue 34): at most 250 lines, and every file it links to exists
(the manual in docs/ is checked by ``mkdocs build --strict``; the README is not part of the site)."""

from __future__ import annotations

import re

from tests.support import ROOT

README = ROOT / "README.md"


def test_readme_is_short():
    lines = README.read_text().splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines; the manual belongs in docs/"


def test_every_relative_link_of_the_readme_exists():
    targets = re.findall(r"\]\(([^)\s]+)\)", README.read_text())
    local = [t.split("#", 1)[0] for t in targets if not re.match(r"[a-z]+:", t) and not t.startswith("#")]
    assert len(local) >= 10  # the tour links into the manual
    missing = sorted({t for t in local if not (ROOT / t).exists()})
    assert not missing, f"README.md links to files that do not exist: {missing}"
