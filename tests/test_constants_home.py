"""One home for each constant: the numbers below are typed once in exporters/ and blender_addon/ (at their
definition, with its source) and imported everywhere else.  Reads the source with ast: literals in code
count, prose in docstrings and comments does not."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: literal -> the (file, name) assignments allowed to hold it.  Everything else must import the name.
HOMES: dict[float, set[tuple[str, str]]] = {
    1.4: {("exporters/constants.py", "N_TISSUE")},  # tissue refractive index (Donner & Jensen 2006)
    1.01: {("exporters/reflectance_tables.py", "IOR_MIN")},  # Cycles' IOR clamp (closure/bssrdf.h)
    3.8: {("exporters/reflectance_tables.py", "IOR_MAX")},
    0.9: {("exporters/cycles.py", "G_MAX")},  # Cycles' anisotropy clamp (closure/bssrdf.h)
    # the inference memory budget (MiB); N_RADIAL_BINS is another 512 (docs/contracts.md §1 profile bins), the bake
    # benchmark's image side yet another, and the bytes a bake band holds per texel another
    512: {("exporters/inference.py", "DEFAULT_MEMORY_MB"), ("exporters/constants.py", "N_RADIAL_BINS"),
          ("exporters/bench.py", "side"), ("exporters/bake/job.py", "BAND_TEXEL_BYTES")},
}


def _assigned_name(parents: list[ast.AST], node: ast.Constant) -> str | None:
    """The name a literal is assigned to (``X = lit``, ``X: T = lit``, ``A, B = l1, l2``, ``x = lit if c else
    ...``), or None when it stands elsewhere (an argument, a default, an expression)."""
    for parent in reversed(parents):
        if isinstance(parent, ast.AnnAssign) and isinstance(parent.target, ast.Name):
            return parent.target.id
        if isinstance(parent, ast.Assign) and len(parent.targets) == 1:
            target = parent.targets[0]
            if isinstance(target, ast.Name):
                return target.id
            if isinstance(target, ast.Tuple) and isinstance(parent.value, ast.Tuple):
                for name, value in zip(target.elts, parent.value.elts, strict=False):
                    if value is node and isinstance(name, ast.Name):
                        return name.id
            return None
        if isinstance(parent, (ast.FunctionDef, ast.ClassDef, ast.Call, ast.arguments)):
            return None
    return None


def _literals(path: Path) -> list[tuple[float, str | None, int]]:
    """(value, assigned name, line) of every int/float literal in a file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []

    def walk(node: ast.AST, parents: list[ast.AST]) -> None:
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            found.append((node.value, _assigned_name(parents, node), node.lineno))
        for child in ast.iter_child_nodes(node):
            walk(child, [*parents, node])

    walk(tree, [])
    return found


def test_each_constant_is_typed_once():
    stray = []
    for folder in ("exporters", "blender_addon"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for value, name, line in _literals(path):
                for literal, homes in HOMES.items():
                    if value == literal and (rel, name) not in homes:
                        stray.append(f"{rel}:{line}: {value!r} (import the named constant: {sorted(homes)})")
    assert not stray, "\n".join(stray)


def test_the_homes_exist():
    """Each allowed home holds its literal (so the test above checks something); the benchmark's may have
    moved out of exporters/."""
    for literal, homes in HOMES.items():
        for rel, name in homes:
            path = ROOT / rel
            if rel.endswith("bench.py") and not path.exists():
                continue
            assert any(v == literal and n == name for v, n, _ in _literals(path)), (literal, rel, name)


def test_the_finder_sees_arguments_and_defaults(tmp_path):
    """The literal in an argument or a default is found (not taken for an assignment)."""
    src = tmp_path / "x.py"
    src.write_text("A = 1.4\nB, C = 1.01, 3.8\ndef f(n=1.4):\n    return g(ior=3.8)\nD = h(512)\n")
    assert sorted(((v, n) for v, n, _ in _literals(src)), key=str) == sorted(
        [(1.01, "B"), (1.4, None), (1.4, "A"), (3.8, None), (3.8, "C"), (512, None)], key=str)
