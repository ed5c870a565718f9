"""Every ```python block of README.md and docs/*.md runs as written.

Each block runs as a script in a fresh interpreter, in a temporary folder where
``scenarios`` and ``docs`` link to the repository's (so a block reads the files
the text names and writes nothing into the repository). A block marked
``<!-- fragment: reason -->`` on the line before its fence is not run: it is a
piece of a larger program (it re-registers a built-in id, or uses an object
from elsewhere), and the reason says which. A block that needs an optional
extra (``pip install -e '.[envs]'``) is skipped when the extra is absent.

A ```text block that follows a python block (blank lines between them only) is
the output the text quotes for it: each of its lines must be a line of what the
block prints, in that order (a line ``...`` stands for lines left out).
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
         *sorted((ROOT / "docs" / "methods").glob("*.md"))]
LINKED = ("scenarios", "docs")  # what the blocks read by relative path
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```[ \t]*$", re.S | re.M)
FRAGMENT = re.compile(r"^<!--\s*fragment:(.*?)-->\s*$")
#: A name in a block -> the modules of the optional extra it needs.
EXTRAS = {"parallel_env": ("pettingzoo", "gymnasium"), "vector_env": ("gymnasium",),
          "gymnasium": ("gymnasium",), "sb3_vec_env": ("stable_baselines3",),
          "torchrl_env": ("torchrl",), "torchrl": ("torchrl",), "to_mcap": ("rosbags",)}


def _blocks() -> list:
    params = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        lines = text.splitlines()
        fences = list(FENCE.finditer(text))
        for i, m in enumerate(fences):
            if m.group(1) != "python":
                continue
            line = text.count("\n", 0, m.start()) + 1
            mark = FRAGMENT.match(lines[line - 2]) if line > 1 else None
            nxt = fences[i + 1] if i + 1 < len(fences) else None
            output = None
            if nxt is not None and nxt.group(1) == "text" and not text[m.end():nxt.start()].strip():
                output = nxt.group(2)
            name = f"{page.relative_to(ROOT).as_posix()}:{line}"
            params.append(pytest.param(m.group(2), output, mark.group(1).strip() if mark else None,
                                       id=name))
    return params


BLOCKS = _blocks()


def test_the_pages_have_their_examples() -> None:
    ids = [p.id for p in BLOCKS]
    assert sum(i.startswith("README.md:") for i in ids) >= 2, ids  # the rest is in docs/
    assert any(i.startswith("docs/python.md:") for i in ids), ids
    assert any(i.startswith("docs/methods/") for i in ids), ids


def test_every_fragment_gives_its_reason() -> None:
    for p in BLOCKS:
        _, _, fragment = p.values
        assert fragment is None or fragment, f"{p.id}: <!-- fragment: --> without a reason"


@pytest.mark.parametrize("code, output, fragment", BLOCKS)
def test_the_example_runs(code: str, output: str | None, fragment: str | None,
                          tmp_path: Path) -> None:
    if fragment is not None:
        pytest.skip(f"fragment: {fragment}")
    for name, modules in EXTRAS.items():
        if re.search(rf"\b{name}\b", code):
            for module in modules:
                if importlib.util.find_spec(module) is None:
                    pytest.skip(f"needs {module} (pip install -e '.[envs,rl]')")
    for name in LINKED:
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    (tmp_path / "example.py").write_text(code, encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if k not in ("DFCOA_PLUGINS", "PYTHONSTARTUP")}
    env["MPLBACKEND"] = "Agg"
    proc = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, env=env, text=True,
                          capture_output=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    if output is not None:
        printed = [line.rstrip() for line in proc.stdout.splitlines()]
        at = 0
        for want in (line.rstrip() for line in output.splitlines()):
            if want in ("", "..."):
                continue
            assert want in printed[at:], (f"the text quotes {want!r}, the block prints:\n"
                                          + proc.stdout[-3000:])
            at = printed.index(want, at) + 1
