"""Controllers from files (--plugin, DFCOA_PLUGINS, a sweep's plugins) and from packages.

Every test that loads a plugin runs in a subprocess, so that this process's
registry (and the sweeps of other tests that say ``controllers = ["*"]``) never
sees it.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from dfcoa_opt.control import registry
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.core.registry import CONTROLLERS

ROOT = Path(__file__).resolve().parents[1]
OBSTACLES = (ROOT / "scenarios" / "example_obstacles.toml").as_posix()


def _block(doc: Path, pattern: str) -> str:
    """The fenced block of ``doc`` whose first line matches ``pattern`` (info string included)."""
    blocks = re.findall(r"^```([^\n]*)\n(.*?)^```$", doc.read_text(), re.S | re.M)
    found = [body for info, body in blocks if re.search(pattern, f"{info}\n{body}")]
    assert len(found) == 1, f"{doc.name}: {len(found)} blocks match {pattern!r}"
    return found[0]


def _dfcoa(*args: str, cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dfcoa_opt", *args], cwd=cwd, text=True,
                          capture_output=True, timeout=300, env={**os.environ, **(env or {})})


@pytest.fixture
def capped(tmp_path: Path) -> Path:
    """The README's "Add your own controller" example, as capped.py."""
    path = tmp_path / "capped.py"
    path.write_text(_block(ROOT / "README.md", r'@d\.register\("capped_goto"\)'))
    return path


def test_the_readme_controller_runs_with_plugin_and_not_without(capped: Path) -> None:
    proc = _dfcoa("run", OBSTACLES, "--plugin", "capped.py", "--controller", "capped_goto",
                  "--json", "--out", "out", cwd=capped.parent)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["controller"] == "capped_goto"
    proc = _dfcoa("run", OBSTACLES, "--controller", "capped_goto", cwd=capped.parent)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "unknown controller 'capped_goto'" in proc.stderr and "--plugin" in proc.stderr


def test_dfcoa_plugins_names_files_for_every_command(capped: Path) -> None:
    proc = _dfcoa("list", "controllers", cwd=capped.parent,
                  env={"DFCOA_PLUGINS": os.pathsep.join(["", str(capped)])})
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"^capped_goto\b", proc.stdout, re.M)
    assert "capped_goto" not in _dfcoa("list", "controllers", cwd=capped.parent).stdout


@pytest.mark.parametrize(("plugin", "message"), [
    ("nope.py", r"--plugin: nope\.py: plugin file not found"),
    ("no_such_module_here", r"--plugin: no_such_module_here: no such module or \.py file"),
    ("broken.py", r"--plugin: broken\.py: importing it raised ZeroDivisionError: division by "
                  r"zero"),
])
def test_a_bad_plugin_is_one_line(tmp_path: Path, plugin: str, message: str) -> None:
    (tmp_path / "broken.py").write_text("x = 1\ny = x / 0\n")
    proc = _dfcoa("run", OBSTACLES, "--plugin", plugin, cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert re.search(message, proc.stderr)


def test_a_sweep_names_its_plugins_and_its_workers_load_them(capped: Path) -> None:
    folder = capped.parent / "sweeps"
    folder.mkdir()
    (folder / "capped.toml").write_text(
        f'scenarios = ["{OBSTACLES}"]\nplugins = ["../capped.py"]\n'
        'controllers = ["capped_goto", "goto_slot"]\nseeds = 2\n[grid]\nt_max = [3.0]\n')
    proc = _dfcoa("bench", "sweeps/capped.toml", "--out", "res", "--jobs", "2",
                  "--no-progress", cwd=capped.parent)
    assert proc.returncode == 0, proc.stderr
    rows = [json.loads(p.read_text()) for p in (capped.parent / "res" / "rows").glob("*.json")]
    assert sorted((r["variant"], r["status"]) for r in rows) == [
        ("capped_goto", "ok"), ("capped_goto", "ok"), ("goto_slot", "ok"), ("goto_slot", "ok")]
    codes = {r["variant"]: r["code"] for r in rows}
    # the plugin file's bytes are part of the run's identity: editing it reruns its runs only
    capped.write_text(capped.read_text().replace("0.4", "0.3"))
    proc = _dfcoa("bench", "sweeps/capped.toml", "--out", "res", "--jobs", "2",
                  "--no-progress", cwd=capped.parent)
    assert proc.returncode == 0, proc.stderr
    assert "ran 2 (0 failed), 2 already done" in proc.stdout
    again = {json.loads(p.read_text())["variant"]: json.loads(p.read_text())["code"]
             for p in (capped.parent / "res" / "rows").glob("*.json")}
    assert again["goto_slot"] == codes["goto_slot"] and again["capped_goto"] != codes[
        "capped_goto"]


def test_a_missing_sweep_plugin_names_the_sweep_file(tmp_path: Path) -> None:
    (tmp_path / "s.toml").write_text(f'scenarios = ["{OBSTACLES}"]\nplugins = ["gone.py"]\n')
    proc = _dfcoa("bench", "s.toml", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert re.search(r"s\.toml: plugins\[0\]: .*gone\.py: plugin file not found", proc.stderr)


def test_a_script_without_a_main_guard_sweeps_on_worker_processes(tmp_path: Path) -> None:
    # multiprocessing would run the script again in every worker: the sweep would start
    # again there and the pool break
    script = tmp_path / "s.py"
    script.write_text(
        "import dfcoa_opt as d\nprint('top level')\n"
        f"res = d.sweep({{'scenarios': ['{OBSTACLES}'], 'controllers': ['goto_slot'], "
        "'seeds': 2}, 'res', jobs=2, overrides={'t_max': 3.0})\n"
        "print(sorted(r['seed'] for r in res.rows))\n")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, text=True,
                          capture_output=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.splitlines() == ["top level", "[0, 1]"]


def test_the_documented_package_installs_and_registers_its_entry_point(tmp_path: Path) -> None:
    doc = ROOT / "docs" / "controllers.md"
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "pyproject.toml").write_text(_block(doc, r'title="pyproject\.toml"'))
    (pkg / "my_controllers.py").write_text(_block(doc, r'title="my_controllers\.py"'))
    site = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                           "--target", str(site), str(pkg)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    env = {"PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    proc = _dfcoa("run", OBSTACLES, "--controller", "capped_goto", "--json", "--out", "out",
                  cwd=tmp_path, env=env)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["controller"] == "capped_goto"


def test_an_entry_point_named_unlike_its_register_id_is_an_error(monkeypatch) -> None:
    registry.available()  # the built-ins into the real registry first (imported once only)
    monkeypatch.setattr(CONTROLLERS, "_loaded", False)
    monkeypatch.setattr(CONTROLLERS, "_table", dict(CONTROLLERS._table))
    @dataclass(frozen=True)
    class Params:
        pass

    cls = registry.register("my_id")(type("Mine", (), {"Params": Params}))

    class EntryPoint:
        name = "other_name"
        value = "my_pkg:Mine"
        module = "my_pkg"

        def load(self):
            return cls

    monkeypatch.setattr(CONTROLLERS, "entry_points", lambda: [EntryPoint()])
    with pytest.raises(DfcoaError, match=r"entry point 'other_name' .* loads Mine, which "
                                         r"@register names 'my_id': name the entry point "
                                         r"'my_id'"):
        registry.available()
    EntryPoint.name = "my_id"  # the same name: one controller, listed once
    monkeypatch.setattr(CONTROLLERS, "_loaded", False)
    assert registry.available().count("my_id") == 1
