"""The house keeps its layers: every import, at the top of a module or inside a function, points
down the data flow (devices and file formats, then face and runtime, then the live session, then
views and commands), and no chain of imports comes back to where it started."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

LAYERS = [
    ("devices", "puppet.errors"),
    ("puppet.fap",),
    ("puppet.io",),
    ("puppet.face",),
    ("puppet.runtime",),
    ("puppet.photo",),
    ("puppet.live",),
    ("puppet.view",),
    ("puppet.show",),
    ("puppet.bench",),
    ("puppet.cli", "puppet"),
]
"""Bottom first. A module may import its own layer's modules and those of the layers below."""


def _modules() -> dict[str, Path]:
    found = {}
    for path in sorted([*ROOT.glob("puppet/**/*.py"), *ROOT.glob("devices/**/*.py")]):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


MODULES = _modules()


def layer(module: str) -> int:
    """The layer of a module: its longest prefix in ``LAYERS``."""
    best, depth = None, -1
    for number, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and prefix.count(".") > depth:
                best, depth = number, prefix.count(".")
    assert best is not None, f"{module} is in no layer: add it to LAYERS"
    return best


def imports(module: str) -> set[str]:
    """The project modules ``module`` imports anywhere in its text (top level or in a function)."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([node.module] if node.module else []))
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
        else:
            continue
        for name in names:
            while name and name not in MODULES:
                name = name.rpartition(".")[0]
            if name and name != module:
                out.add(name)
    return out


GRAPH = {module: imports(module) for module in MODULES}


def test_every_module_is_in_a_layer():
    for module in MODULES:
        layer(module)


def test_no_import_points_up_a_layer():
    upward = sorted(f"{a} -> {b}" for a, targets in GRAPH.items() for b in targets
                    if layer(b) > layer(a) and not (a == "puppet" or b == "puppet"))
    assert not upward


def test_devices_import_nothing_of_puppet():
    assert not sorted(f"{a} -> {b}" for a, targets in GRAPH.items() if a.startswith("devices")
                      for b in targets if b.startswith("puppet"))


def test_no_import_circle():
    """Tarjan's strongly connected components: every one is a single module."""
    index, low, stack, on_stack, circles = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH[v] - {"puppet"}:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    sys.setrecursionlimit(10_000)
    for v in GRAPH:
        if v not in index:
            visit(v)
    assert not circles


@pytest.mark.parametrize("module", ["puppet.io", "puppet.io.fapfile", "puppet.io.takes", "puppet.live.retake",
                                    "puppet.live.session"])
def test_headless_layers_load_no_renderer(module):
    """File formats and headless rebuilds (a replay, a session) import no moderngl."""
    code = f"import sys, {module}; print(sorted(m for m in ('moderngl', 'pyglet', 'imgui_bundle') if m in sys.modules))"
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]"
