"""The docs and notebooks name no folder of one machine: an absolute path (/work/..., /home/...,
/tmp/..., C:\\Users\\...) works on the machine it was written on and nowhere else. Examples use
the bundled maps by name (`load_envmap("forest_slope")`, `thinfilm_jax/data/envmaps`),
paths relative to the repository, or a placeholder (PATH/TO/map.hdr); temporary folders come
from `tempfile.gettempdir()`."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: an absolute path into a machine's own folders, not part of a URL (https://host/home/...)
MACHINE_PATH = re.compile(
    r"(?<![\w.~/:-])/(?:work|home|root|tmp|Users|mnt|scratch|var/folders|private/var)/"
    r"|\b[A-Za-z]:\\\\?(?:Users|Documents and Settings)\b")
FILES = sorted([*ROOT.glob("docs/**/*.md"), *ROOT.glob("notebooks/*.ipynb"),
                ROOT / "README.md", ROOT / "mkdocs.yml"])


def machine_paths(text: str) -> list[str]:
    """The lines of `text` that name an absolute machine path."""
    return [line.strip() for line in text.splitlines() if MACHINE_PATH.search(line)]


def test_the_check_sees_machine_paths_and_not_urls():
    assert machine_paths("render --envmap /work/shared/envmaps/a.hdr")
    assert machine_paths('OUT = "/tmp/out"') and machine_paths("see /home/me/x.hdr")
    assert machine_paths(r"C:\Users\me\map.hdr")
    assert not machine_paths("https://polyhaven.com/home/a and docs/how-to/render.md")
    assert not machine_paths("thinfilm_jax/data/envmaps/forest_slope_256.hdr, ../old, ~/tmp/")


@pytest.mark.parametrize("path", FILES, ids=[str(p.relative_to(ROOT)) for p in FILES])
def test_no_absolute_machine_paths(path):
    found = machine_paths(path.read_text(encoding="utf-8"))
    assert not found, f"{path.relative_to(ROOT)} names a folder of one machine: {found}"
