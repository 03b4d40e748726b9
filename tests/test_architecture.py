"""The package's shape: one top-level name, layers that only point down."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# bottom first; modules of one layer may import each other
LAYERS = [
    {"eosp", "eosp.config", "eosp.errors", "eosp.atomic", "eosp.args", "eosp.memory", "eosp.ownership"},
    {"eosp.sim"},
    {"eosp.graphs"},
    {"eosp.instances"},
    {"eosp.shards"},
    {"eosp.fleet"},
    {"eosp.envs"},
    {"eosp.models"},
    {"eosp.search"},
    {"eosp.solvers"},
    {"eosp.training"},
    {"eosp.evaluation"},
    {"eosp.jobs"},
    {"eosp.cli"},
]


def package_dirs() -> dict[str, Path]:
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    return {pkg: ROOT / folder for pkg, folder in cfg["package-dir"].items()}


def layer_of(module: str) -> int:
    best = None
    for i, names in enumerate(LAYERS):
        for name in names:
            if module == name or (name != "eosp" and module.startswith(name + ".")):
                best = i
    if best is None:
        raise AssertionError(f"module {module} belongs to no layer: add it to LAYERS and docs/architecture.md")
    return best


def modules() -> list[tuple[str, Path]]:
    out = []
    for pkg, folder in package_dirs().items():
        for f in sorted(folder.glob("*.py")):
            name = pkg if f.stem == "__init__" else f"{pkg}.{f.stem}"
            out.append((name, f))
    return out


def imported(path: Path, module: str) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the module's package
                base = module.rsplit(".", node.level)[0] if path.stem != "__init__" else module
                names.add(f"{base}.{node.module}" if node.module else base)
            elif node.module:
                names.add(node.module)
                names |= {f"{node.module}.{a.name}" for a in node.names if node.module == "eosp"}
    return {n for n in names if n == "eosp" or n.startswith("eosp.")}


def test_every_module_is_in_a_layer_and_imports_only_downwards():
    mods = modules()
    assert len(mods) > 40
    bad = []
    for name, path in mods:
        mine = layer_of(name)
        for target in imported(path, name):
            if target == "eosp":
                continue
            theirs = layer_of(target)
            if theirs > mine:
                bad.append(f"{name} ({path.relative_to(ROOT)}) imports {target}, a higher layer")
    assert not bad, "\n".join(bad)


def test_layer_check_catches_an_upward_import(tmp_path):
    f = tmp_path / "mod.py"
    f.write_text("def f():\n    from eosp.solvers.greedy import solve\n")
    assert "eosp.solvers.greedy" in imported(f, "eosp.models.mod")
    assert layer_of("eosp.solvers.greedy") > layer_of("eosp.models.mod")


def test_no_sys_path_edits_outside_tests():
    offenders = []
    for f in ROOT.rglob("*.py"):
        rel = f.relative_to(ROOT)
        if rel.parts[0] in ("tests", ".venv", "build") or "site-packages" in rel.parts:
            continue
        if "sys.path.insert" in f.read_text() or "sys.path.append" in f.read_text():
            offenders.append(str(rel))
    assert not offenders


def test_no_init_in_platform():
    assert not (ROOT / "platform" / "__init__.py").exists()


def test_wheel_holds_one_top_level_package_and_builds_without_warnings(tmp_path):
    # built from a copy of the tracked files: a build writes build/ and *.egg-info beside its sources
    src = tmp_path / "src"
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for rel in filter(None, tracked.decode().split("\0")):
        if (ROOT / rel).is_file():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, src / rel)
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w",
                        str(tmp_path), str(src)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    log = r.stdout + r.stderr
    assert "Warning" not in log and "absent from the `packages`" not in log, log
    (wheel,) = tmp_path.glob("eosp-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert top == {"eosp"}, top
    for sub in ("envs", "models", "jobs", "sim", "cli", "training", "solvers", "search"):
        assert f"eosp/{sub}/__init__.py" in names
    assert "eosp/config.py" in names and "eosp/jobs/train.py" in names
