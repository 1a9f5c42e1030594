"""The layers of the code base point down: a static check of the import graph (``ast``, nothing imported).

Every module of ``exporters``, ``blender_addon`` and ``training`` is parsed; each ``import`` / ``from ... import``
(at module level or inside a function) is an edge from its module to the module it names.  Modules belong to
the packages of ``LAYERS`` (lowest first); an edge may only point to the same package or a lower one.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOPS = ("exporters", "blender_addon", "training")
#: Lowest first.  ``exporters`` is the shipped runtime, ``blender_addon`` the add-on over it; inside ``training``
#: the science packages, then the studies that use them, the benchmarks, the demo's renders and the command line.
LAYERS: tuple[str, ...] = (
    "exporters",
    "blender_addon",
    "training",  # training/__init__.py: a docstring
    "training.paths",
    "training.cluster",
    "training.demo_subject",
    "training.skin",
    "training.sim",
    "training.data",
    "training.fit",
    "training.model",
    "training.train",
    "training.export",
    "training.realskin",
    "training.validate",
    "training.ablations",
    "training.demo_render",
    "training.openpbr_check",
    "training.oblique_render",
    "training.bench",
    "training.commands",
    "training.__main__",
)


#: ``blender_addon.core.<m>`` is ``exporters.<m>`` (blender_addon/core.py resolves the core beside the add-on).
CORE_ALIAS = ("exporters.", "blender_addon.core.")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for top in TOPS for p in sorted((ROOT / top).rglob("*.py"))}


def imports(name: str, path: Path) -> set[str]:
    """Every module ``path`` imports (absolute names; relative imports resolved; ``from a import b`` also
    gives ``a.b``, which may be a module)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.add(target)
            found |= {f"{target}.{alias.name}" for alias in node.names}
    return {CORE_ALIAS[0] + n[len(CORE_ALIAS[1]):] if n.startswith(CORE_ALIAS[1]) else n for n in found}


def graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (external packages dropped)."""
    mods = modules()
    edges = {}
    for name, path in mods.items():
        edges[name] = {t for t in imports(name, path) if t in mods}
    return edges


def layer(module: str) -> int:
    """Index in LAYERS of the longest entry that is ``module`` or a package holding it."""
    best = max((entry for entry in LAYERS if module == entry or module.startswith(entry + ".")), key=len,
               default=None)
    assert best is not None, f"{module} belongs to no layer: add its package to LAYERS in tests/test_layers.py"
    return LAYERS.index(best)


def upward(edges: dict[str, set[str]]) -> list[str]:
    return sorted(f"{a} -> {b}" for a, targets in edges.items() for b in targets if layer(b) > layer(a))


def package_cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected sets of more than one LAYERS package (Tarjan's algorithm on the package graph)."""
    pkg: dict[str, set[str]] = defaultdict(set)
    for a, targets in edges.items():
        for b in targets:
            if LAYERS[layer(a)] != LAYERS[layer(b)]:
                pkg[LAYERS[layer(a)]].add(LAYERS[layer(b)])
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(pkg[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(pkg):
        if v not in index:
            visit(v)
    return out


def test_the_graph_is_read():
    edges = graph()
    assert len(edges) > 120
    assert "training.sim.lut_interp" in edges["training.fit.loss"]  # a module-level import
    assert "training.sim.lut_extend" in edges["training.sim.lut_interp"]  # a function-local one
    assert "exporters.painted" in edges["exporters.collapse"] and "exporters.cycles" in edges["blender_addon.nodes"]


def test_no_import_points_up():
    assert upward(graph()) == []


def test_no_import_cycle_between_packages():
    assert package_cycles(graph()) == []


def test_the_checks_catch_a_bad_import():
    edges = {k: set(v) for k, v in graph().items()}
    edges["training.sim.lut_interp"].add("training.fit.loss")  # sim -> fit: up, and a cycle with fit -> sim
    assert upward(edges) == ["training.sim.lut_interp -> training.fit.loss"]
    cycles = package_cycles(edges)  # one strongly connected set: fit and sim, with any package on a path between
    assert len(cycles) == 1 and {"training.fit", "training.sim"} <= set(cycles[0]), cycles


def test_exporters_is_the_runtime_only():
    """No torch, bpy or training; no benchmark, no Mitsuba module, no ``__main__`` entry point."""
    for name, path in modules().items():
        if not name.startswith("exporters"):
            continue
        tree = ast.parse(path.read_text())
        names = imports(name, path)
        assert not {n for n in names if n.split(".")[0] in {"torch", "bpy", "training", "mitsuba"}}, name
        assert "bench" not in name and "mitsuba" not in name, name
        mains = [n for n in ast.walk(tree) if isinstance(n, ast.Compare) and isinstance(n.left, ast.Name)
                 and n.left.id == "__name__"]
        assert not mains, f"{name} has an `if __name__ == ...` entry point: make it a `python -m training` command"


def test_the_addon_never_imports_training():
    edges = graph()
    bad = [f"{a} -> {b}" for a, targets in edges.items() if a.startswith("blender_addon")
           for b in targets if b.startswith("training")]
    assert bad == []
    for name, path in modules().items():
        if name.startswith("blender_addon"):
            assert not {n for n in imports(name, path) if n.split(".")[0] == "training"}, name


def test_the_shipped_model_paths_come_from_the_addon_without_bpy():
    """training takes the shipped model's paths from blender_addon/models/__init__.py, loaded by its file."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['bpy'] = None\n"
            "from training import paths\n"
            "assert paths.SHIPPED_MODEL.name == 'skin_inversion.onnx' and paths.SHIPPED_MODEL.is_file()\n"
            "assert all(p.is_file() for p in (paths.SHIPPED_DECODER, paths.SHIPPED_TABLE, paths.SHIPPED_CARD))\n"
            "assert paths.SHIPPED_MODEL_DIR == paths.REPO_ROOT / 'blender_addon' / 'models'\n"
            "assert not [m for m in sys.modules if m.startswith('blender_addon')]")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr


def test_the_extension_imports_itself_relatively():
    """Installed, ``exporters`` and ``blender_addon`` are subpackages of the extension (bl_ext.<repo>.<id>):
    an absolute ``import exporters`` or ``from blender_addon import`` in them would import a top-level module that
    is not there (or another add-on's)."""
    bad = []
    for name, path in modules().items():
        if name.split(".")[0] not in ("exporters", "blender_addon"):
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                bad += [f"{name}: import {a.name}" for a in node.names if a.name.split(".")[0] in TOPS]
            elif isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").split(".")[0] in TOPS:
                bad.append(f"{name}: from {node.module} import ...")
    assert bad == []
