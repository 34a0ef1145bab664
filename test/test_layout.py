"""The package layout holds (issue 10): one folder per concern, rclpy only in ``ros/``,
exception types in one module, no import cycle, no giant module.

These read the sources with ``ast`` (no import of the modules, except the boundary test,
which imports every module in a subprocess where rclpy cannot be imported).
"""

import ast
import os
import subprocess
import sys
import textwrap
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "grasp_apso"
MODULES = sorted(p for p in PKG.rglob("*.py") if "__pycache__" not in p.parts)


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """Modules of grasp_apso that ``path`` imports anywhere (absolute names)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    me = _module_name(path)
    package = me if path.name == "__init__.py" else me.rsplit(".", 1)[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("grasp_apso"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if not mod.startswith("grasp_apso"):
                continue
            for alias in node.names:
                candidate = f"{mod}.{alias.name}"
                out.add(candidate if _exists(candidate) else mod)
    return out


def _exists(name: str) -> bool:
    rel = Path(*name.split("."))
    return (ROOT / rel).with_suffix(".py").exists() or (ROOT / rel / "__init__.py").exists()


def test_rclpy_is_imported_only_inside_ros():
    offenders = []
    for path in MODULES:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names = [node.module]
            if any(n.split(".")[0] in ("rclpy", "rcl_interfaces", "grasp_apso_interfaces") for n in names):
                if path.relative_to(PKG).parts[0] != "ros":
                    offenders.append(str(path.relative_to(ROOT)))
    assert offenders == []


def test_every_module_outside_ros_imports_without_rclpy(tmp_path):
    """A subprocess where ``import rclpy`` fails imports every non-ROS module."""
    blocker = tmp_path / "blocker"
    blocker.mkdir()
    for name in ("rclpy", "rcl_interfaces", "grasp_apso_interfaces"):
        (blocker / name).mkdir()
        (blocker / name / "__init__.py").write_text(f"raise ImportError('{name} is blocked in this test')\n")
    names = [_module_name(p) for p in MODULES if p.relative_to(PKG).parts[0] != "ros"]
    code = textwrap.dedent(f"""
        import importlib, sys
        bad = []
        for name in {names!r}:
            try:
                importlib.import_module(name)
            except Exception as exc:
                bad.append(f"{{name}}: {{type(exc).__name__}}: {{exc}}")
        assert "rclpy" not in sys.modules or sys.modules["rclpy"] is None
        print("\\n".join(bad))
        sys.exit(1 if bad else 0)
    """)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(blocker), str(ROOT)]), MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert len(names) > 30


def test_ros_does_not_import_tools():
    """The node's wording and colours come from ``presentation/``, shared with ``tools/``:
    ``ros/`` never imports the command-line package (nor ``presentation/`` anything of it)."""
    offenders = sorted(
        f"{p.relative_to(ROOT)} -> {m}" for p in MODULES if p.relative_to(PKG).parts[0] in ("ros", "presentation")
        for m in _imports(p) if m == "grasp_apso.tools" or m.startswith("grasp_apso.tools."))
    assert offenders == []


def test_no_import_cycle_between_modules():
    graph = {_module_name(p): {m for m in _imports(p) if m != _module_name(p)} for p in MODULES}
    # A package's __init__ importing nothing is the norm here; edges to packages count too.
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if nxt not in graph:
                continue
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt] if nxt in stack else [node, nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for start in sorted(graph):
        if start not in state:
            visit(start, [start])
    assert cycles == []


def test_module_sizes():
    sizes = {str(p.relative_to(ROOT)): len(p.read_text(encoding="utf-8").splitlines()) for p in MODULES}
    assert {k: v for k, v in sizes.items() if v > 600} == {}
    assert sizes["grasp_apso/ros/node.py"] <= 350


def test_exception_types_are_defined_in_one_module():
    where = defaultdict(list)
    for path in MODULES:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef):
                bases = {getattr(b, "id", getattr(b, "attr", "")) for b in node.bases}
                if node.name.endswith(("Error", "Exceeded")) or bases & {"Exception", "ValueError", "RuntimeError"}:
                    where[str(path.relative_to(ROOT))].append(node.name)
    assert set(where) <= {"grasp_apso/errors.py"}, dict(where)


def test_sub_packages_are_the_documented_ones():
    folders = {p.name for p in PKG.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    architecture = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    for folder in folders:
        assert f" {folder}/ " in architecture or f"`{folder}/`" in architecture, f"docs/architecture.md does not describe {folder}/"
    assert {"model", "geometry", "quality", "search", "ros", "tools"} <= folders


@pytest.mark.parametrize("path", [p for p in MODULES if p.name != "__init__.py"], ids=lambda p: str(p.relative_to(PKG)))
def test_every_module_has_a_docstring(path):
    assert ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))), f"{path} has no module docstring"
