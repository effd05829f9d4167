"""Structure guards over EVERY import statement of the product (module level, inside functions, under
``TYPE_CHECKING``): no import cycle, no upward arrow between the top packages (robocal imports nothing of
campaign or drivers; drivers nothing of campaign), the rooms of campaign/ and of robocal/ import only the rooms
before them, every room names what it offers (``__all__``) and a name crosses from one room to another only
through that list, no private name (``_name``) imported from another module and no private module from another
package, no module over the line cap, the line bridge's import closure is the standard library only, the cell
model is built where a command starts (one nominal-model call site), an installed copy holds every package, and
docs/architecture.md names every module and shows the rooms as the code has them.

Known debt is listed with the reason it is still here; every list fails when an entry goes stale, so it cannot
outlive the debt. ``test_checker_*`` run the same checks on small fake trees so that each check is shown to fail.
"""
from __future__ import annotations

import ast
import functools
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("campaign", "robocal", "drivers")
RANK = {"robocal": 0, "drivers": 1, "campaign": 2}        # a package may import only packages of lower rank
MAX_LINES = 500
# The rooms of campaign/ and robocal/ along their data flow, lowest first; a room imports only rooms listed before
# it. campaign's shared bottom (errors; io: durable files, JSON fields, safe CSV cells, terminal text, redaction)
# imports no room above it.
CAMPAIGN_LAYERS = ("errors", "io", "config", "plan", "run", "data", "calibrate", "correct", "report", "workflows",
                   "cli", "__main__")
ROBOCAL_LAYERS = ("kinematics", "measure", "identify", "effects", "layers", "multi_smr", "correct", "design",
                  "simulation", "diagnose", "iso9283")
ROOMS = {"campaign": CAMPAIGN_LAYERS, "robocal": ROBOCAL_LAYERS}
SHARED_LEAVES = {"campaign": {"errors", "io"}, "robocal": set()}
BRIDGE = "drivers.bridge.line_bridge"

# Known debt (issue 23 removes every entry). Each entry says why it is here.
OVER_LIMIT: dict[str, str] = {}      # file -> why it is still over MAX_LINES
KNOWN_CYCLES = {}
KNOWN_UPWARD: dict[tuple[str, str], str] = {}   # (importer, imported): arrows from a lower package to a higher one
KNOWN_DOWNWARD: dict[tuple[str, str], str] = {}  # (importer, imported): a campaign room importing a room above it
KNOWN_PRIVATE: dict[tuple[str, str, str], str] = {}   # (importer, defining module, name)
KNOWN_CLOSED_DOORS: dict[str, str] = {}   # a door rule broken (the message of door_violations) -> why
# The numerics of a config are built once per command and passed down (campaign.config.cell_model.CellModel):
# call (or import, for a function) -> the only files (a folder ends in /) that may make it.
CELL_BUILDERS = {
    "nominal_kinematics": ("campaign/config/cell_model.py",),
    "CellModel.from_config": ("campaign/config/load.py",),                      # inside load_cell
    "load_cell": ("campaign/cli/", "campaign/workflows.py", "campaign/config/load.py",
                  "campaign/run/emscon_cell.py"),                              # the emulator's command entry
}
KNOWN_CELL_BUILDERS: dict[tuple[str, str], str] = {}   # (file, call): a builder outside CELL_BUILDERS


@dataclass(frozen=True)
class Edge:
    """One imported project module (``target``) named by an import statement of ``source`` at ``line``;
    ``name`` is the imported name when the statement is ``from target import name`` (else None)."""
    source: str
    target: str
    name: str | None
    line: int


def parsed(path: Path) -> ast.Module:
    """The syntax tree of a file (parsed and walked once per text: every check reads the same files)."""
    return _walked(path.read_text(encoding="utf-8"))[0]


def walked(path: Path) -> tuple[ast.AST, ...]:
    """The import statements and the calls of the file, anywhere in it (``ast.walk`` order: inside functions,
    classes and ``if`` blocks included)."""
    return _walked(path.read_text(encoding="utf-8"))[1]


@functools.lru_cache(maxsize=None)
def _walked(text: str) -> tuple[ast.Module, tuple[ast.AST, ...]]:
    tree = ast.parse(text)
    return tree, tuple(n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom, ast.Call)))


def modules(root: Path, packages=PACKAGES) -> dict[str, Path]:
    """Dotted module name -> file, for every .py file under the packages."""
    out = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def package_of(name: str, path: Path) -> str:
    """The package a module belongs to (a package's ``__init__`` belongs to the package itself)."""
    return name if path.name == "__init__.py" else name.rpartition(".")[0]


def import_edges(name: str, path: Path, known: dict[str, Path]) -> list[Edge]:
    """Every import statement of the file (``ast.walk``: functions, classes, ``if`` blocks included), resolved
    to project modules; ``from pkg import submodule`` names the submodule."""
    base = package_of(name, path).split(".")
    edges = []
    for node in walked(path):
        if isinstance(node, ast.Import):
            pairs = [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                mod = ".".join(base[: len(base) - node.level + 1] + ([mod] if mod else []))
            pairs = [(f"{mod}.{a.name}", None) if f"{mod}.{a.name}" in known else (mod, a.name) for a in node.names]
        else:
            continue
        for target, imported in pairs:
            while target and target not in known:
                target, imported = target.rpartition(".")[0], None
            if target and target != name:
                edges.append(Edge(name, target, imported, node.lineno))
    return edges


def graph(root: Path, packages=PACKAGES) -> tuple[dict[str, Path], list[Edge]]:
    """The modules and every import edge between them (a package's ``__init__`` importing its own submodules
    is no edge: it only hands names on)."""
    mods = modules(root, packages)
    edges = [e for n, p in mods.items() for e in import_edges(n, p, mods)
             if not (mods[n].name == "__init__.py" and e.target.startswith(n + "."))]
    return mods, edges


def cycles(mods: dict[str, Path], edges: list[Edge]) -> list[frozenset[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    succ: dict[str, set[str]] = {n: set() for n in mods}
    for e in edges:
        succ[e.source].add(e.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found = []
    for start in sorted(mods):
        if start in index:
            continue
        work = [(start, iter(sorted(succ[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on.add(start)
        while work:
            node, it = work[-1]
            nxt = next(it, None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on.add(nxt)
                    work.append((nxt, iter(sorted(succ[nxt]))))
                elif nxt in on:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = set()
                while True:
                    m = stack.pop()
                    on.discard(m)
                    comp.add(m)
                    if m == node:
                        break
                if len(comp) > 1:
                    found.append(frozenset(comp))
    return found


def describe(comp: frozenset[str], edges: list[Edge], mods: dict[str, Path], root: Path) -> str:
    """The edges inside one cycle, as ``file:line -> module``."""
    inner = sorted({(str(mods[e.source].relative_to(root)), e.line, e.target) for e in edges
                    if e.source in comp and e.target in comp})
    return "; ".join(f"{f}:{line} -> {t}" for f, line, t in inner)


def upward(edges: list[Edge]) -> set[tuple[str, str]]:
    """(importer, imported) pairs from a lower top package to a higher one."""
    return {(e.source, e.target) for e in edges
            if RANK.get(e.target.split(".")[0], -1) > RANK.get(e.source.split(".")[0], 99)}


def layer_of(module: str) -> tuple[str, int] | None:
    """(package, index of the module's room in ``ROOMS[package]``; -1 in none) for a module of a package with
    rooms, None for anything else (a package's own ``__init__``, drivers)."""
    parts = module.split(".")
    if parts[0] not in ROOMS or len(parts) == 1:
        return None
    return parts[0], ROOMS[parts[0]].index(parts[1]) if parts[1] in ROOMS[parts[0]] else -1


def layer_violations(mods: dict[str, Path], edges: list[Edge]) -> list[str]:
    """Modules of campaign/ and robocal/ outside their room tables, and imports of a room at or above the
    importer's own room (siblings inside one room are free; a shared leaf imports no room but the leaves)."""
    out = [f"{m}: in no room of ROOMS[{m.split('.')[0]!r}]" for m in sorted(mods) if (layer_of(m) or ("", 0))[1] == -1]
    for e in edges:
        a, b = layer_of(e.source), layer_of(e.target)
        if a is None or b is None or a[0] != b[0] or a[1] < 0 or b[1] < 0:
            continue
        src, dst = e.source.split(".")[1], e.target.split(".")[1]
        leaves = SHARED_LEAVES[a[0]]
        if src != dst and (b[1] > a[1] or (src in leaves and dst not in leaves)):
            out.append(f"{e.source}:{e.line} imports {e.target} (a room above it)")
    return out


def private_imports(mods: dict[str, Path], edges: list[Edge]) -> set[tuple[str, str, str]]:
    """(importer, defining module, name) of ``_private`` names imported from another module, and (importer,
    module, "") of a private module (``_common.py``) imported from outside its package: a name shared between
    modules is public; a room keeps its shared internals in a private module of its own."""
    names = {(e.source, e.target, e.name) for e in edges if e.name and is_private(e.name)}
    return names | {(e.source, e.target, "") for e in edges if is_private(e.target.rpartition(".")[2])
                    and package_of(e.source, mods[e.source]) != package_of(e.target, mods[e.target])}


def is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def room_of(module: str) -> str | None:
    """The room a module belongs to: ``campaign.run``, ``robocal.kinematics``, ``drivers`` (drivers' own modules)
    or ``drivers.rapid`` (a sub-package); None for the root ``__init__`` of campaign and robocal."""
    parts = module.split(".")
    if parts[0] == "drivers":
        return ".".join(parts[:2]) if len(parts) > 2 or (len(parts) == 2 and parts[1] in DRIVER_ROOMS) else "drivers"
    return ".".join(parts[:2]) if len(parts) > 1 else None


DRIVER_ROOMS = ("bridge", "emulators", "rapid")        # drivers' sub-packages, each a room of its own


ENTRY_MODULES = ("__main__",)    # a module run as a program (``python -m campaign``) is no room: it offers nothing


def door(mods: dict[str, Path], room: str) -> dict[str, str] | None:
    """What a room offers: each name of its ``__all__`` -> the module that defines it. The door is the room's
    ``__init__`` (or the module of a one-module room); a name's home is read from the ``_HOMES`` table (module ->
    names, loaded on first use), a ``_LAZY`` table (name -> module) or a ``from .module import name`` of the
    ``__init__``; any other name is defined by the door's file itself. A computed ``__all__`` (not a literal list)
    is the names of ``_HOMES`` and the strings it spells out. None when the file has no ``__all__``."""
    tree = parsed(mods[room])
    homes: dict[str, str] = {}          # name -> module, from _HOMES, _LAZY and relative imports
    lazy: list[str] = []                # the names of _HOMES, in order
    listed: list[str] | None = None     # a literal __all__
    computed = False
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module and mods[room].name == "__init__.py":
            homes |= {a.asname or a.name: f"{room}.{node.module}" for a in node.names}
        target = node.targets[0] if isinstance(node, ast.Assign) and len(node.targets) == 1 else \
            node.target if isinstance(node, ast.AnnAssign) and node.value is not None else None
        if not isinstance(target, ast.Name):
            continue
        if target.id == "_HOMES":
            lazy = [n for names in ast.literal_eval(node.value).values() for n in names]
            homes |= {n: f"{room}.{m}" for m, names in ast.literal_eval(node.value).items() for n in names}
        elif target.id == "_LAZY":
            homes |= {n: f"{room}.{m}" for n, m in ast.literal_eval(node.value).items()}
        elif target.id == "__all__":
            literal = isinstance(node.value, (ast.List, ast.Tuple)) and all(isinstance(e, ast.Constant)
                                                                             for e in node.value.elts)
            listed = list(ast.literal_eval(node.value)) if literal else [
                c.value for c in ast.walk(node.value) if isinstance(c, ast.Constant) and isinstance(c.value, str)]
            computed = not literal
    if computed:
        listed = (listed or []) + lazy
    return None if listed is None else {n: homes.get(n, room) for n in listed}


def defines(path: Path, name: str) -> bool:
    """The module binds ``name`` at its top level itself (a def, a class, an assignment), not by importing it."""
    for node in parsed(path).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.name == name:
            return True
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) \
            else []
        if any(isinstance(n, ast.Name) and n.id == name for t in targets for n in ast.walk(t)):
            return True
    return False


def offers(mods: dict[str, Path], module: str, name: str, depth: int = 0) -> bool:
    """The module defines ``name`` or hands it on from a module of its own package that does (``from .x import
    name`` or ``from package.x import name``): either way the name lives where the door says."""
    if defines(mods[module], name):
        return True
    base = package_of(module, mods[module])
    for node in parsed(mods[module]).body:
        if isinstance(node, ast.ImportFrom) and node.module and node.level <= 1 and depth < 3:
            source = f"{base}.{node.module}" if node.level else node.module
            if source.rpartition(".")[0] != base:
                continue
            for a in node.names:
                if (a.asname or a.name) == name and source in mods and offers(mods, source, a.name, depth + 1):
                    return True
    return False


def door_violations(mods: dict[str, Path], edges: list[Edge]) -> list[str]:
    """Every room has a door (``__all__``); each name on it is defined in the module the door names and is not
    also a module of the room; a module imports another room's names only, and only names on its door."""
    rooms = sorted({r for m in mods if (r := room_of(m)) is not None and r in mods
                    and r.rpartition(".")[2] not in ENTRY_MODULES})
    doors = {r: door(mods, r) for r in rooms}
    out = [f"{r}: no __all__ (what the room offers) in {mods[r].name}" for r in rooms if doors[r] is None]
    for r, names in doors.items():
        for name, home in sorted((names or {}).items()):
            if home not in mods or not offers(mods, home, name):
                out.append(f"{r}: {name} is not defined in {home}")
            elif f"{r}.{name}" in mods:
                out.append(f"{r}: {name} is both a public name and a module of the room")
    for e in edges:
        src, dst = room_of(e.source), room_of(e.target)
        if src == dst or dst is None or src is None or dst not in doors:
            continue
        if e.name is None:
            out.append(f"{e.source}:{e.line} imports the module {e.target} of another room (import its names)")
        elif e.name not in (doors.get(dst) or {}):
            out.append(f"{e.source}:{e.line} imports {e.name} from {e.target}, not on the door of {dst}")
    return out


def third_party_closure(root: Path, start: str) -> dict[str, set[str]]:
    """Module of the import closure of ``start`` (project modules followed) -> the non-standard-library,
    non-project top-level modules it imports."""
    mods = modules(root)
    todo, seen, out = [start], set(), {}
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        tree = parsed(mods[name])
        tops = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        tops |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                 and n.module and not n.level}
        out[name] = {t for t in tops if t not in sys.stdlib_module_names and t not in PACKAGES}
        todo += [e.target for e in import_edges(name, mods[name], mods)]
    return out


def builder_sites(root: Path, builders=CELL_BUILDERS, packages=PACKAGES) -> set[tuple[str, str, int]]:
    """(file, builder, line) of every call of a ``builders`` key outside the files it allows: a call whose dotted
    callee is the key or ends with ``.key``; for a plain function also any import of it (an alias is a call site)."""
    out = set()
    for path in modules(root, packages).values():
        rel = path.relative_to(root).as_posix()
        for node in walked(path):
            names = [a.name for a in node.names] if isinstance(node, ast.ImportFrom) else []
            if isinstance(node, ast.Call):
                names = [dotted(node.func)]
            for key, allowed in builders.items():
                if any(n == key or n.endswith(f".{key}") for n in names) \
                        and not any(rel == a or (a.endswith("/") and rel.startswith(a)) for a in allowed):
                    out.add((rel, key, node.lineno))
    return out


def dotted(func: ast.expr) -> str:
    """``a.b.c`` of a callee made of names and attributes ("" for anything else: a call's result, a subscript)."""
    parts = []
    while isinstance(func, ast.Attribute):
        parts.append(func.attr)
        func = func.value
    return ".".join([func.id, *reversed(parts)]) if isinstance(func, ast.Name) else ""


# ----------------------------------------------------------------------------------------------------------------
# the product

@functools.lru_cache(maxsize=1)
def product_graph() -> tuple[dict[str, Path], list[Edge]]:
    """The product's modules and import edges, drawn once per session (the structure and docs tests share it)."""
    return graph(ROOT)


@pytest.fixture(scope="module")
def product():
    return product_graph()


@pytest.mark.unit
def test_no_import_cycle(product):
    mods, edges = product
    found = cycles(mods, edges)
    new = [c for c in found if not any(c <= known for known in KNOWN_CYCLES)]
    assert not new, "import cycle (imports inside functions count): " + " | ".join(
        describe(c, edges, mods, ROOT) for c in new)
    stale = [sorted(k) for k in KNOWN_CYCLES if not any(c & k for c in found)]
    assert not stale, f"no longer a cycle, remove from KNOWN_CYCLES: {stale}"


@pytest.mark.unit
def test_no_upward_import(product):
    _, edges = product
    found = upward(edges)
    assert found <= set(KNOWN_UPWARD), f"upward (robocal < drivers < campaign): {sorted(found - set(KNOWN_UPWARD))}"
    assert not set(KNOWN_UPWARD) - found, f"gone, remove from KNOWN_UPWARD: {sorted(set(KNOWN_UPWARD) - found)}"


@pytest.mark.unit
def test_rooms_import_downward(product):
    """Every module of campaign/ and robocal/ is in a room and imports only the rooms before its own."""
    mods, edges = product
    found = layer_violations(mods, edges)
    known = {v for v in found for a, b in KNOWN_DOWNWARD if v.startswith(f"{a}:") and f" imports {b} " in v}
    assert set(found) <= known, f"rooms importing upward: {sorted(set(found) - known)}"
    stale = [k for k in KNOWN_DOWNWARD if not any(v.startswith(f"{k[0]}:") and f" imports {k[1]} " in v for v in found)]
    assert not stale, f"gone, remove from KNOWN_DOWNWARD: {stale}"


@pytest.mark.unit
def test_no_private_name_imported_from_another_module(product):
    mods, edges = product
    found = private_imports(mods, edges)
    assert found <= set(KNOWN_PRIVATE), ("private names imported from another module, or private modules from "
                                         "another package (make them public, join the modules, or share a "
                                         f"_common module of the room): {sorted(found - set(KNOWN_PRIVATE))}")
    assert not set(KNOWN_PRIVATE) - found, f"gone, remove from KNOWN_PRIVATE: {sorted(set(KNOWN_PRIVATE) - found)}"


@pytest.mark.unit
def test_every_room_names_what_it_offers(product):
    """Each room's door (``__all__`` in its ``__init__``, or in the module of a one-module room) lists the names it
    offers; another room imports those names and nothing else of it."""
    mods, edges = product
    found = door_violations(mods, edges)
    assert set(found) <= set(KNOWN_CLOSED_DOORS), "\n".join(sorted(set(found) - set(KNOWN_CLOSED_DOORS)))
    assert not set(KNOWN_CLOSED_DOORS) - set(found), f"gone: {sorted(set(KNOWN_CLOSED_DOORS) - set(found))}"


@pytest.mark.unit
def test_an_installed_copy_holds_every_package():
    """pyproject.toml's package list is the tree's packages (an installed, non-editable copy has every room)."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]["packages"])
    tree = {package_of(n, p) for n, p in modules(ROOT).items() if p.name == "__init__.py"}
    assert listed == tree, f"missing from pyproject.toml: {sorted(tree - listed)}; not a package: {sorted(listed - tree)}"


@pytest.mark.unit
def test_module_size_cap():
    sizes = {str(p.relative_to(ROOT)): len(p.read_text(encoding="utf-8").splitlines()) for p in modules(ROOT).values()}
    over = {f: n for f, n in sizes.items() if n > MAX_LINES}
    assert set(over) <= set(OVER_LIMIT), f"over {MAX_LINES} lines: {sorted(set(over) - set(OVER_LIMIT))}"
    stale = sorted(f for f in OVER_LIMIT if sizes.get(f, 0) <= MAX_LINES)
    assert not stale, f"no longer over the limit, remove from OVER_LIMIT: {stale}"


@pytest.mark.unit
def test_cell_model_is_built_once_where_a_command_starts():
    """One call of ``nominal_kinematics`` (in CellModel.from_config); the cell model is built by ``load_cell`` in
    the CLI and the workflows and passed down, never rebuilt from a config below them."""
    found = builder_sites(ROOT)
    new = sorted(f for f in found if f[:2] not in KNOWN_CELL_BUILDERS)
    assert not new, f"cell model built outside {CELL_BUILDERS} (pass the CellModel down instead): {new}"
    stale = sorted(set(KNOWN_CELL_BUILDERS) - {f[:2] for f in found})
    assert not stale, f"gone, remove from KNOWN_CELL_BUILDERS: {stale}"
    text = (ROOT / "campaign/config/cell_model.py").read_text(encoding="utf-8")
    calls = [n for n in ast.walk(ast.parse(text)) if isinstance(n, ast.Call)
             and dotted(n.func).split(".")[-1] == "nominal_kinematics"]
    assert len(calls) == 1, f"campaign/config/cell_model.py calls nominal_kinematics {len(calls)} times, expected 1"


@pytest.mark.unit
def test_line_bridge_needs_no_third_party_package():
    """The reference bridge runs on a PC with only Python and the vendor SDK: its import closure is the standard
    library and the project's own stdlib-only modules."""
    closure = third_party_closure(ROOT, BRIDGE)
    assert not {m: t for m, t in closure.items() if t}, closure


# ----------------------------------------------------------------------------------------------------------------
# the checks themselves, on fake trees

def _tree(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


CLEAN = {"robocal/__init__.py": "", "robocal/kinematics/__init__.py": "", "robocal/kinematics/kin.py": "import numpy\n",
         "drivers/__init__.py": "", "drivers/mock.py": "from robocal.kinematics.kin import numpy\n",
         "campaign/__init__.py": "", "campaign/config/__init__.py": "",
         "campaign/config/schema.py": "from campaign.errors import E\n", "campaign/errors.py": "E = 1\n",
         "campaign/run/__init__.py": "",
         "campaign/run/runner.py": "from ..config.schema import E\nfrom .log import x\nfrom ._common import y\n",
         "campaign/run/log.py": "x = 1\n_x = 2\n", "campaign/run/_common.py": "y = 1\n"}


def _clean_plus(tmp_path: Path, extra: dict[str, str]):
    """The graph of CLEAN with ``extra`` text appended to (or forming) some of its files."""
    files = dict(CLEAN)
    for rel, text in extra.items():
        files[rel] = files.get(rel, "") + text
    return graph(_tree(tmp_path, files))


@pytest.mark.unit
def test_checker_passes_a_clean_tree(tmp_path):
    mods, edges = graph(_tree(tmp_path, CLEAN))
    assert not cycles(mods, edges) and not upward(edges) and not private_imports(mods, edges)
    assert not layer_violations(mods, edges)
    assert any(e.target == "campaign.run._common" for e in edges)       # a room's own _common module is free


@pytest.mark.unit
def test_checker_finds_a_robocal_room_importing_a_later_one(tmp_path):
    mods, edges = _clean_plus(tmp_path, {"robocal/identify/__init__.py": "", "robocal/identify/fit.py":
                                         "from robocal.kinematics.kin import numpy\n",
                                         "robocal/kinematics/kin.py": "def f():\n    from ..identify.fit import g\n"})
    assert layer_violations(mods, edges) == ["robocal.kinematics.kin:3 imports robocal.identify.fit (a room above it)"]


@pytest.mark.unit
def test_checker_finds_a_cycle_through_an_import_inside_a_function(tmp_path):
    mods, edges = _clean_plus(tmp_path, {"campaign/config/schema.py":
                                         "def load():\n    from campaign.run.runner import E\n    return E\n"})
    assert cycles(mods, edges) == [frozenset({"campaign.config.schema", "campaign.run.runner"})]
    assert "campaign/config/schema.py:3 -> campaign.run.runner" in describe(cycles(mods, edges)[0], edges, mods,
                                                                             tmp_path)
    assert any("imports campaign.run.runner" in v for v in layer_violations(mods, edges))


@pytest.mark.unit
def test_checker_finds_a_cycle_under_type_checking_and_a_relative_one(tmp_path):
    typing_only = "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import runner\n"
    mods, edges = _clean_plus(tmp_path, {"campaign/run/log.py": typing_only})
    assert cycles(mods, edges) == [frozenset({"campaign.run.log", "campaign.run.runner"})]


@pytest.mark.unit
def test_checker_finds_upward_arrows_private_names_and_closures(tmp_path):
    mods, edges = _clean_plus(tmp_path, {
        "robocal/kinematics/kin.py": "def f():\n    import campaign.errors\n",
        "drivers/mock.py": "from campaign.run.log import _x\nfrom campaign.run._common import y\n",
        "campaign/run/runner.py": "from .log import _x\n",
        "campaign/cli/__init__.py": "", "campaign/cli/main.py": "from campaign.config.schema import E\n",
        "campaign/oddity.py": "", "campaign/io/__init__.py": "",
        "campaign/io/json_fields.py": "from campaign.errors import E\nfrom campaign.config.schema import E\n"})
    assert upward(edges) == {("robocal.kinematics.kin", "campaign.errors"), ("drivers.mock", "campaign.run.log"),
                             ("drivers.mock", "campaign.run._common")}
    assert private_imports(mods, edges) == {("drivers.mock", "campaign.run.log", "_x"),       # across packages,
                                            ("campaign.run.runner", "campaign.run.log", "_x"),  # inside one,
                                            ("drivers.mock", "campaign.run._common", "")}     # a room's _common
    assert layer_violations(mods, edges) == [              # io, the shared bottom, may import errors only
        "campaign.oddity: in no room of ROOMS['campaign']",
        "campaign.io.json_fields:2 imports campaign.config.schema (a room above it)"]
    assert third_party_closure(tmp_path, "drivers.mock") == {
        "drivers.mock": set(), "robocal.kinematics.kin": {"numpy"}, "campaign.run.log": set(),
        "campaign.run._common": set(), "campaign.errors": set()}


@pytest.mark.unit
def test_checker_finds_a_second_cell_builder(tmp_path):
    root = _tree(tmp_path, {**CLEAN, "campaign/config/cell_model.py": "def nominal_kinematics(cfg):\n    pass\n"
                                                                      "k = nominal_kinematics(1)\n",
                            "campaign/cli/main.py": "from campaign.config.load import load_cell\nc = load_cell(1)\n"})
    assert not builder_sites(root)
    _tree(tmp_path, {"campaign/plan/build.py": "from campaign.config import cell_model as cm\n"
                                               "def f(cfg):\n    return cm.nominal_kinematics(cfg)\n",
                     "campaign/run/eta.py": "from campaign.config.cell_model import nominal_kinematics as nk\n",
                     "campaign/data/x.py": "from campaign.config.cell_model import CellModel\n"
                                           "c = CellModel.from_config(1)\n",
                     "drivers/mock.py": "import campaign.config.load\ncampaign.config.load.load_cell(2)\n"})
    assert builder_sites(root) == {("campaign/plan/build.py", "nominal_kinematics", 3),
                                   ("campaign/run/eta.py", "nominal_kinematics", 1),
                                   ("campaign/data/x.py", "CellModel.from_config", 2),
                                   ("drivers/mock.py", "load_cell", 2)}


@pytest.mark.unit
def test_checker_reads_doors_and_finds_names_past_them(tmp_path):
    lazy = ('"""The plan."""\nfrom robocal import lazy_exports\n_HOMES = {"points": ("Plan",)}\n'
            '__all__ = ["version", *(n for names in _HOMES.values() for n in names)]\n'
            '__getattr__ = lazy_exports(__name__, _HOMES)\nversion = 1\n')
    mods, edges = _clean_plus(tmp_path, {
        "campaign/plan/__init__.py": lazy, "campaign/plan/points.py": "class Plan:\n    pass\n_P = 2\nQ = 3\n",
        "campaign/errors.py": '__all__ = ["E"]\n', "campaign/config/__init__.py": "__all__ = []\n",
        "campaign/run/__init__.py": "from .log import x\n__all__ = ['x', 'ghost']\n",
        "campaign/__main__.py": "from campaign.run.log import x\n",
        "campaign/run/runner.py": "from campaign.plan.points import Plan, Q\nfrom campaign.plan import points\n"})
    assert door(mods, "campaign.plan") == {"version": "campaign.plan", "Plan": "campaign.plan.points"}
    assert door(mods, "campaign.run") == {"x": "campaign.run.log", "ghost": "campaign.run"}
    assert sorted(door_violations(mods, edges)) == [      # __main__ is no room: it needs no __all__
        "campaign.run.runner:1 imports E from campaign.config.schema, not on the door of campaign.config",
        "campaign.run.runner:4 imports Q from campaign.plan.points, not on the door of campaign.plan",
        "campaign.run.runner:5 imports the module campaign.plan.points of another room (import its names)",
        "campaign.run: ghost is not defined in campaign.run",
        "drivers.mock:1 imports numpy from robocal.kinematics.kin, not on the door of robocal.kinematics",
        "drivers: no __all__ (what the room offers) in __init__.py",
        "robocal.kinematics: no __all__ (what the room offers) in __init__.py"]
