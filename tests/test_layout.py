"""The package's imports go one way: from the API down through the pipeline to its stages.

Every module of ``baker`` belongs to one layer of ``LAYERS`` (lowest first); a module may import
modules of its own layer or of lower ones, never of a higher one, and no set of modules imports
itself round in a circle. Imports inside functions count as much as those at the top (a lazy
import that goes back up is still a circle); only ``if TYPE_CHECKING:`` imports, which never
run, are left out. The checker is tested on made-up graphs too, so that it is known to fail.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "baker"

# Lowest first. A module belongs to the longest prefix that names it.
LAYERS = (
    ("baker.errors", "baker.jit", "baker.frozen", "baker.rowwise"),  # errors; compiled kernels;
    # read-only hand-offs; products summed row by row
    ("baker.run",),  # processes, threads, progress, spilled rows, atomic files
    ("baker.settings",),  # what the user may set
    ("baker.materials", "baker.punctual"),  # materials and lights as the estimators see them
    ("baker.gltf",),  # reading glTF into a Scene; what its materials mean
    ("baker.geometry",),  # the world's triangles; what a surface looks like
    ("baker.rays",),  # sample points and Embree
    ("baker.atlas",),  # unwrap, authored UVs, rasterise, validity, supersample
    ("baker.context",),  # what every estimator needs of a bake, made once
    ("baker.light",),  # obscurance terms, translucency, direct light, ambient, GI
    ("baker.image",),  # compose, post-process, seams, denoise, encode, float files
    ("baker.output",),  # the glTF written back
    ("baker.pipeline",),  # the plan, the parts, the full bake
    ("baker.rebake",),  # the bake state, what changed, the incremental rebake
    ("baker.api", "baker.preview", "baker.study", "baker.view"),  # what a user calls
    ("baker",),  # the package's public names (its __init__)
    ("baker.cli", "baker.__main__"),  # the command line, a user of those names; python -m baker
)


def module_name(path: Path) -> str:
    """``baker/light/direct.py`` → ``baker.light.direct``; a package's ``__init__`` is the package."""
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_only(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def imports_of(path: Path, modules: set[str]) -> set[str]:
    """The baker modules that ``path`` imports, at any depth but ``if TYPE_CHECKING:``."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        if _type_checking_only(node):
            return
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)  # `from pkg import mod`
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text()))
    return {m for m in found if m in modules and m != name}


def layer_of(module: str) -> int:
    """Index in ``LAYERS`` of the longest prefix naming ``module``; KeyError if none does."""
    best, length = None, -1
    for i, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > length:
                best, length = i, len(prefix)
    if best is None:
        raise KeyError(module)
    return best


def graph() -> dict[str, set[str]]:
    """Every module of the package → the package's modules it imports."""
    paths = sorted(PACKAGE.rglob("*.py"))
    modules = {module_name(p) for p in paths}
    return {module_name(p): imports_of(p, modules) for p in paths}


def upward(imports: dict[str, set[str]]) -> list[str]:
    """``a → b`` for every import of a module of a higher layer than ``a``'s."""
    return sorted(f"{a} → {b}" for a, deps in imports.items() for b in deps
                  if layer_of(b) > layer_of(a))


def circles(imports: dict[str, set[str]]) -> list[list[str]]:
    """The import circles: strongly connected sets of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(imports.get(v, ())):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in sorted(imports):
        if v not in index:
            connect(v)
    return found


def test_every_module_has_a_layer():
    unplaced = []
    for module in graph():
        try:
            layer_of(module)
        except KeyError:
            unplaced.append(module)
    assert not unplaced, f"add these modules to a layer of LAYERS: {unplaced}"


def test_no_import_goes_up():
    assert upward(graph()) == []


def test_no_import_circle():
    assert circles(graph()) == []


def test_the_checks_find_what_they_look_for():
    """A made-up graph with a circle within one layer and an import of a higher layer."""
    made_up = {"baker.light.a": {"baker.light.b"}, "baker.light.b": {"baker.light.a"},
               "baker.atlas.c": {"baker.light.a"}, "baker.api": {"baker.light.a"}}
    assert circles(made_up) == [["baker.light.a", "baker.light.b"]]
    assert upward(made_up) == ["baker.atlas.c → baker.light.a"]


def test_imports_are_read_at_any_depth_but_type_checking(tmp_path):
    source = tmp_path / "m.py"
    source.write_text("from typing import TYPE_CHECKING\n"
                      "if TYPE_CHECKING:\n    from baker.api import bake\n"
                      "def f():\n    from baker.light import direct\n")
    modules = {"baker.api", "baker.light", "baker.light.direct"}
    global PACKAGE
    saved, PACKAGE = PACKAGE, tmp_path.parent
    try:
        assert imports_of(source, modules) == {"baker.light", "baker.light.direct"}
    finally:
        PACKAGE = saved



def test_the_estimators_never_import_the_gltf_layer():
    """``baker/light/`` reads the scene through ``context.Context`` (world, materials, tracer,
    lights, settings) and the format-free records (``materials``, ``punctual``), never through
    ``baker.gltf``: the estimators know nothing of the file format (lazy imports included)."""
    imports = graph()
    found = sorted(f"{a} → {b}" for a, deps in imports.items() if a.startswith("baker.light")
                   for b in deps if b == "baker.gltf" or b.startswith("baker.gltf."))
    assert found == []


def test_the_design_table_names_every_module():
    """docs/design.md §3's table names every package of ``baker`` and every module in it: a
    module added without its line there fails here, so the design stays true to the code."""
    text = (PACKAGE.parent / "docs" / "design.md").read_text()
    table = [line for line in text.splitlines() if line.startswith("| `")]
    rows = {cell.strip("`"): line for line in table
            for cell in line.split("|")[1].replace(",", " ").split()}
    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).parts
        if len(parts) == 1:
            if path.name not in ("__init__.py", "__main__.py") and path.name not in rows:
                missing.append(path.name)
        elif path.name != "__init__.py":
            row = rows.get(f"{parts[0]}/")
            if row is None or f"`{path.stem}`" not in row:
                missing.append(f"{parts[0]}/{path.name}")
    assert missing == []


def test_the_design_lists_the_full_bake_s_stages():
    """docs/design.md §3's stage table names the stages of ``pipeline.full.STAGES``, in their
    order (read from the source, the names being the lines a bake prints): a stage added,
    renamed or moved without its row there fails here."""
    tree = ast.parse((PACKAGE / "pipeline" / "full.py").read_text())
    listed = next(node.value for node in tree.body if isinstance(node, ast.AnnAssign)
                  and ast.unparse(node.target) == "STAGES")
    stages = [call.args[0].value for call in listed.elts]
    lines = (PACKAGE.parent / "docs" / "design.md").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| stage "))
    rows = []
    for line in lines[start + 2:]:  # past the header and its rule, to the table's end
        if not line.startswith("|"):
            break
        rows.append(line.split("|")[1].strip().split(" (")[0])
    assert rows == stages


def test_the_command_line_goes_through_the_api():
    """The command line reaches the bake only through the API (``baker``'s public names,
    ``baker.api``, ``preview``, ``study``, ``view``), never into the pipeline's stages, so the
    stages can change behind the API without the CLI noticing."""
    stages = ("baker.pipeline", "baker.rebake", "baker.light", "baker.atlas", "baker.image",
              "baker.output", "baker.geometry", "baker.rays")
    modules = {module_name(path) for path in PACKAGE.rglob("*.py")}
    reached = {module_name(path): sorted(m for m in imports_of(path, modules)
                                         if m.startswith(stages))
               for path in (PACKAGE / "cli").glob("*.py")}
    text = {name: found for name, found in reached.items() if found}
    attribute = {str(path.name): sorted(set(re.findall(r"\bbaker\.(?:%s)\.\w+" % "|".join(
        s.split(".")[1] for s in stages), path.read_text())))
        for path in (PACKAGE / "cli").glob("*.py")}
    assert text == {} and {k: v for k, v in attribute.items() if v} == {}
