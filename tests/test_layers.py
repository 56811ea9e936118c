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


def test_no_module_imports_a_higher_layer():
    upward = []
    for name, path in modules().items():
        mine = package_of(name)
        for other in imports(name, path):
            theirs = package_of(other)
            if RANK[theirs] > RANK[mine]:
                upward.append(f"{name} ({mine}) imports {other} ({theirs})")
    assert not upward, "upward imports:\n" + "\n".join(sorted(upward))


def test_no_two_packages_import_each_other():
    edges = set()
    for name, path in modules().items():
        mine = package_of(name)
        edges.update((mine, package_of(o)) for o in imports(name, path) if package_of(o) != mine)
    cycles = sorted(f"{a} <-> {b}" for a, b in edges if (b, a) in edges and a < b)
    assert not cycles, "packages importing each other: " + ", ".join(cycles)


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
