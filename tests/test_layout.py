"""README's "## Layout" names every module of the package once, and nothing else."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_layout_matches_tree():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("\n## Layout\n", 1)[1].split("\n## ", 1)[0]
    listed = re.findall(r"^\| `([^`]+\.py)` \|", section, flags=re.M)
    package = ROOT / "thinfilm_jax"
    modules = sorted(str(p.relative_to(package)) for p in package.rglob("*.py"))
    assert len(listed) == len(set(listed)), "a module is listed twice"
    missing, extra = sorted(set(modules) - set(listed)), sorted(set(listed) - set(modules))
    assert not missing and not extra, f"add to README Layout: {missing}; remove: {extra}"
