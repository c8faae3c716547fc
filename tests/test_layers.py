"""The architecture's import rules (docs/architecture.md), read from the source with `ast`.

Every import counts, also those deferred inside functions or behind TYPE_CHECKING: a
cycle hidden by a deferred import is still a cycle for a reader. The rules:

* `scanmap_driver` never imports `scanmap`; neither package imports `benchmarks`,
  `tests` or `examples`.
* Inside `scanmap`, a module imports only from its own subpackage or from a lower layer
  (`LAYERS`); no module imports the top-level `scanmap` facade.
* There is no import cycle between modules of either package.
* Examples import only public names: `scanmap`, `scanmap_driver` and their subpackages'
  `__init__`s, never a module below them.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# scanmap's subpackages from the bottom up; each may import those before it.
LAYERS = ["stage_clock", "grid", "io", "registration", "navigation", "graph", "mapping",
          "datasets", "evaluation", "pipelines", "cli"]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path) -> set[str]:
    """Absolute names of every module `path` imports (relative imports resolved)."""
    tree = ast.parse(path.read_text(), str(path))
    package = module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                stem = package[: len(package) - node.level + 1]
                base = ".".join([*stem, base] if base else stem)
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def sources(package: str) -> dict[str, Path]:
    return {module_name(p): p for p in (ROOT / package).rglob("*.py")}


MODULES = {**sources("scanmap"), **sources("scanmap_driver")}


def internal_imports(name: str) -> set[str]:
    """The project's own modules that module `name` imports (names cut to a module)."""
    out = set()
    for target in imports_of(MODULES[name]):
        while target and target not in MODULES:
            target = target.rpartition(".")[0]
        if target and target != name:
            out.add(target)
    return out


def layer(name: str) -> int:
    parts = name.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else len(LAYERS)


def test_the_layer_list_names_every_part_of_scanmap():
    parts = {p.stem if p.is_file() else p.name for p in (ROOT / "scanmap").iterdir()
             if not p.name.startswith(("_", ".")) and (p.suffix == ".py" or p.is_dir())}
    assert parts == set(LAYERS)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_module_imports_upwards_or_outside(name):
    imported = imports_of(MODULES[name])
    foreign = {m for m in imported if m.split(".")[0] in ("benchmarks", "tests", "examples")}
    assert not foreign, f"{name} imports {sorted(foreign)}"
    if name.startswith("scanmap_driver"):
        assert not {m for m in imported if m.split(".")[0] == "scanmap"}
        return
    if name == "scanmap":
        return  # the facade may re-export anything
    own = layer(name)
    for target in internal_imports(name):
        if target == "scanmap":
            pytest.fail(f"{name} imports the top-level facade `scanmap`")
        if target.startswith("scanmap."):
            same_part = target.split(".")[1] == name.split(".")[1]
            assert same_part or layer(target) < own, (
                f"{name} (layer {LAYERS[own]}) imports {target} (layer "
                f"{LAYERS[layer(target)]}): imports must point down the layers")


def test_there_is_no_import_cycle():
    graph = {name: internal_imports(name) for name in MODULES}
    state: dict[str, int] = {}  # 1 on the stack, 2 done

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            # A package's __init__ importing its own modules is how packages work.
            if node != "scanmap" and nxt.startswith(node + "."):
                continue
            if state.get(nxt) == 1:
                cycle = stack[stack.index(nxt):] + [nxt] if nxt in stack else [node, nxt]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if state.get(nxt) is None:
                visit(nxt, [*stack, nxt])
        state[node] = 2

    for name in sorted(graph):
        if state.get(name) is None:
            visit(name, [name])


@pytest.mark.parametrize("example", sorted((ROOT / "examples").glob("*.py")), ids=str)
def test_examples_use_only_public_names(example):
    packages = {n for n, p in MODULES.items() if p.name == "__init__.py"}
    for target in imports_of(example):
        top = target.split(".")[0]
        if top not in ("scanmap", "scanmap_driver") or target in packages:
            continue
        parent = target.rpartition(".")[0]
        assert parent in packages and target not in MODULES, (
            f"{example.name} imports {target}: use the public names of "
            f"{parent or top} (its __all__) instead")
        assert not target.rpartition(".")[2].startswith("_")
