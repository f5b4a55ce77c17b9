"""`make figure7`, the README's main job, leaves a checkout as it found it.

A newcomer runs `make figure7`, then `make test`: the job must not dirty the tree, and no
test may then depend on how fast the machine ran it. So the job's output folder holds its
results only (the configuration, the errors against the reference, the band values and the
panels, `thinfilm_jax.render.figure7.run_figure7`), which a rerun on this machine writes
byte for byte; its times go to stdout (and to ``--timing PATH``, which `make bench` uses for
figures/figure7_timing.json, the file the docs' timing sentence quotes).

The check runs the Makefile's own recipe for ``figure7`` (``thinfilm-jax figure7 --out
figures``, the full 64 × 64 job) with this checkout's code, in an empty folder standing for
a fresh clone, and then asks of every file it wrote what ``git status --porcelain`` would
say after the same run in the checkout: nothing. A written file is either ignored by git or
tracked and equal to the checkout's copy, byte for byte (so a rerun in a clean clone shows no
change); an untracked, unignored file would be listed too. Comparing with the working tree,
not HEAD, keeps the check about the code under test while figures are being regenerated.

Time: the job itself, on this project's 2-core machine 13 s with the test run's compilation
cache warm at a load average of 0.5 (8.5 s of computing), 21 s at a load of 8; 37 s with a
fresh cache at a load of 11. One test file, so one work unit of `make test`.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def figure7_recipe() -> list[str]:
    """The arguments of ``thinfilm-jax`` in the Makefile's ``figure7`` recipe (one command)."""
    text = (ROOT / "Makefile").read_text("utf-8")
    m = re.search(r"^figure7:[^\n]*\n((?:\t[^\n]*\n)+)", text, flags=re.M)
    assert m, "no figure7 target in the Makefile"
    lines = [ln.strip() for ln in m.group(1).splitlines()]
    assert len(lines) == 1, f"the figure7 recipe is one command, found {lines}"
    words = shlex.split(lines[0])
    assert words[0] == "$(BIN)/thinfilm-jax", words
    return words[1:]


def _git(*args: str) -> subprocess.CompletedProcess:
    # read-only queries: no index lock, so concurrent commits in the checkout are unaffected
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)


def dirty(written: Path) -> list[str]:
    """What ``git status --porcelain`` would list after the files under `written` (a folder
    standing for the repository root) were written into the checkout."""
    out = []
    for p in sorted(q for q in written.rglob("*") if q.is_file()):
        rel = p.relative_to(written).as_posix()
        if _git("check-ignore", "-q", rel).returncode == 0:
            continue  # ignored: never listed
        if _git("ls-files", "--error-unmatch", rel).returncode != 0:
            out.append(f"?? {rel} (untracked, not ignored)")
        elif not (ROOT / rel).is_file() or (ROOT / rel).read_bytes() != p.read_bytes():
            out.append(f" M {rel} (differs from the checkout's copy)")
    return out


needs_git = pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                               reason="not a git checkout")


@needs_git
def test_dirty_sees_changed_untracked_and_ignored_files(tmp_path):
    """The check itself: a changed tracked file and an untracked one are listed, an identical
    tracked file and an ignored one are not."""
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "figure7.json").write_bytes(
        (ROOT / "figures" / "figure7.json").read_bytes())
    (tmp_path / "figures" / "figure7_error.png").write_bytes(b"not the committed panel")
    (tmp_path / "figures" / "unexpected_new_file.txt").write_text("x")
    (tmp_path / ".test-time").mkdir()
    (tmp_path / ".test-time" / "run.json").write_text("{}")  # .gitignore: .test-time/
    assert dirty(tmp_path) == [
        " M figures/figure7_error.png (differs from the checkout's copy)",
        "?? figures/unexpected_new_file.txt (untracked, not ignored)"]


@needs_git
@pytest.mark.slow
def test_make_figure7_leaves_the_checkout_clean(tmp_path):
    args = figure7_recipe()
    assert args[:1] == ["figure7"] and "--out" in args, args
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "thinfilm_jax", *args],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    written = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")
                     if p.is_file())
    assert "figures/figure7.json" in written and "figures/figure7.png" in written, written
    assert dirty(tmp_path) == [], (
        "`make figure7` would leave these changes in a clean clone (machine-dependent "
        f"output belongs in --timing or stdout; files written: {written}):\n"
        + "\n".join(dirty(tmp_path)))
