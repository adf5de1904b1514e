"""The README's methods table is the registry's (``grisx methods --markdown``), and its pictures exist."""

from __future__ import annotations

import re
from pathlib import Path

from grisx.render.cli import methods_markdown

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def test_readme_methods_table_matches_the_registry():
    block = re.search(r"<!-- methods:start -->\n(.*?)<!-- methods:end -->", README, re.S)
    assert block is not None, "README.md lost its <!-- methods:start/end --> markers"
    assert block.group(1).strip() == methods_markdown().strip(), "README's methods table is stale: paste `grisx methods --markdown`"


def test_readme_pictures_exist():
    for path in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", README):
        assert (ROOT / path).is_file(), path
