"""The packages form layers that point one way (``docs/architecture.md``): a module
never imports a package of a higher layer, and no two packages import each other.

Imports are read from the source (``ast``), at any depth in a module (a function's
deferred import counts as much as one at the top), so the test fails on the commit
that adds an upward import, whatever runs or not.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("twin", "mapgen", "sensors")

#: Bottom to top. A module belongs to the longest package named here that contains it.
LAYERS = (
    ("twin.core",),
    ("mapgen",),
    ("twin.physics",),
    ("sensors",),
    ("twin.traffic",),
    ("twin.data",),
    ("twin.calibration",),
    ("twin.cosim",),
    ("twin.metrics",),
    ("twin.runners",),
    ("twin.control", "twin.export"),
    ("twin.perf", "twin.cli", "twin"),
)
RANK = {package: rank for rank, layer in enumerate(LAYERS) for package in layer}
#: Modules placed apart from their package: ``twin/__init__.py`` holds only the
#: version, which every layer may read; the modules beside it (``python -m twin``
#: and the entry-point aliases) are at the top.
PLACED = {"twin": "twin.core"}


def package_of(module: str) -> str:
    """The package of ``LAYERS`` a dotted module name belongs to."""
    if module in PLACED:
        return PLACED[module]
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        name = ".".join(parts[:k])
        if name in RANK:
            return name
    raise AssertionError(f"{module} belongs to no layer of tests/test_layers.py")


def modules() -> dict[str, Path]:
    found = {}
    for top in SOURCES:
        for path in (ROOT / top).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            found[name.removesuffix(".__init__")] = path
    return found


def imports(name: str, path: Path) -> set[str]:
    """The project modules that module ``name`` (at ``path``) imports, by dotted name."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join([*base, *([node.module] if node.module else [])])
            else:
                module = node.module
            found.add(module)
            # ``from twin import energy``: the submodule is what is imported
            found.update(f"{module}.{alias.name}" for alias in node.names)
    known = modules()
    return {m for m in found if m in known or (m.split(".")[0] in SOURCES and m in known)}


def test_every_module_belongs_to_a_layer():
    for name in modules():
        package_of(name)
    # a new package under twin/ is placed in LAYERS, not taken for the top layer
    packages = {p.parent.name for p in (ROOT / "twin").glob("*/__init__.py")}
    unplaced = sorted(f"twin.{name}" for name in packages if f"twin.{name}" not in RANK)
    assert not unplaced, f"packages missing from LAYERS: {unplaced}"


def test_only_the_physics_package_imports_pybullet():
    outside = []
    for name, path in modules().items():
        if package_of(name) == "twin.physics":
            continue
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            names = (
                [alias.name for alias in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            names += (
                [f"{node.module}.{alias.name}" for alias in node.names]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            if any(n.split(".")[0] == "pybullet" or n == "twin.physics.bullet.pybullet"
                   for n in names):  # fmt: skip
                outside.append(name)
    assert not outside, f"pybullet used outside twin/physics: {sorted(set(outside))}"


def test_no_module_imports_a_higher_layer():
    upward = []
    for name, path in modules().items():
        mine = package_of(name)
        for other in imports(name, path):
            theirs = package_of(other)
            if RANK[theirs] > RANK[mine]:
                upward.append(f"{name} ({mine}) imports {other} ({theirs})")
    assert not upward, "upward imports:\n" + "\n".join(sorted(upward))


def test_no_packages_import_each_other_round_a_cycle():
    graph: dict[str, set[str]] = {}
    for name, path in modules().items():
        mine = package_of(name)
        graph.setdefault(mine, set()).update(
            package_of(o) for o in imports(name, path) if package_of(o) != mine
        )
    cycles = [sorted(c) for c in strongly_connected(graph) if len(c) > 1]
    assert not cycles, f"packages importing each other round a cycle: {cycles}"


def strongly_connected(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of a directed graph (Tarjan's algorithm)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in graph.get(node, ()):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = set()
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.add(top)
                if top == node:
                    break
            out.append(component)

    for node in list(graph):
        if node not in index:
            visit(node)
    return out


def test_the_cycle_search_finds_a_cycle_of_three():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert [sorted(c) for c in strongly_connected(graph) if len(c) > 1] == [["a", "b", "c"]]


@pytest.mark.parametrize(
    "module, expected",
    [
        ("twin.core.i24", "twin.core"),
        ("twin.traffic.models.idm", "twin.traffic"),
        ("twin", "twin.core"),
        ("twin.env", "twin"),
    ],
)
def test_modules_are_placed_in_their_package(module, expected):
    assert package_of(module) == expected
