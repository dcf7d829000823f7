"""The import structure: no cycles, no upward imports between the wings, engines kept in
their adapters.

Every ``import`` and ``from ... import`` anywhere in a module (function bodies and
``if TYPE_CHECKING`` blocks included) of ``validation/`` and ``mini_engine/`` is an edge,
resolved to project modules: ``from validation.x import y`` is an edge to
``validation.x.y`` when ``y`` is a submodule, and an edge to a package is an edge to its
``__init__``. Importing a module also runs its parent packages' ``__init__``, so those are
edges too (except the importer's own ancestors, which Python has already imported before
the importer runs; an *explicit* import of one's own package still counts).
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("mini_engine", "validation", "physval")

WINGS: dict[str, int] = {
    "mini_engine": 0,
    "validation": 1,  # the root __init__: run before every wing, so it sits at the bottom
    "validation.csv_safe": 0,  # spreadsheet-safe CSV cells: imported by every CSV writer and reader
    "validation.redact": 0,  # passwords masked in URLs and command lines: imported by every output
    "validation.bundled": 0,  # where the scene library is: the commands' default paths
    "validation.versions": 0,  # installed versions from package metadata: --version, list
    "validation.contract": 1,
    "validation.engine_api": 1,  # engine declarations and discovery: read by spec parsing
    "validation.files": 1,
    "validation.signals": 2,  # imports contract; imported by jobs, cli and entry
    "validation.reference": 1,  # the closed forms judged against: below all that reads them
    "validation.scenario": 2,
    "validation.engines": 3,
    "validation.measure": 4,
    "validation.report": 4,
    "validation.nightly": 5,
    "validation.jobs": 6,
    "validation.cli": 7,
    "validation.pytest_plugin": 7,
    "physval": 7,  # the Python API: run's, check's and the loader's machinery, as the cli's
    "validation.entry": 8,
}
"""Wing (module prefix) -> rank. A wing may import its own modules and those of lower-ranked
wings, never a higher or an equally ranked other wing (except ``ALSO_ALLOWED``)."""

ALSO_ALLOWED = {("validation.report", "validation.measure")}
"""Equal-rank imports that are allowed: the report reads the metric definitions of measure
(``measure.definitions``); measure never imports report."""

ENGINE_HOMES = {"mujoco": "validation/engines/mujoco/", "pybullet": "validation/engines/pybullet/"}
"""Third-party engine -> the only folder that may import it (``pybullet_data`` and other
``pybullet*`` modules count as pybullet)."""


@dataclass(frozen=True)
class Edge:
    source: str
    target: str
    file: str
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.source} -> {self.target}"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_files() -> dict[str, Path]:
    """Module name -> file, for every .py under the project packages."""
    return {
        module_name(path): path
        for package in PACKAGES
        for path in sorted((ROOT / package).rglob("*.py"))
    }


MODULES = project_files()


def is_package(module: str) -> bool:
    return MODULES[module].name == "__init__.py"


def imported_names(module: str, tree: ast.AST):
    """(line, absolute dotted name) of every import in ``tree``: the module imported, plus
    ``module.name`` for each ``from module import name`` (a submodule if it is one)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                package = module if is_package(module) else module.rpartition(".")[0]
                for _ in range(node.level - 1):
                    package = package.rpartition(".")[0]
                base = ".".join(p for p in (package, node.module or "") if p)
            else:
                base = node.module or ""
            yield node.lineno, base
            for alias in node.names:
                if alias.name != "*":
                    yield node.lineno, f"{base}.{alias.name}"


def ancestors(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:k]) for k in range(1, len(parts))]


def project_edges() -> list[Edge]:
    edges = set()
    for source, path in MODULES.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        own_ancestors = set(ancestors(source))
        for line, name in imported_names(source, tree):
            if name not in MODULES:
                continue  # third-party, or ``from module import function``
            implied = [p for p in ancestors(name) if p not in own_ancestors and p in MODULES]
            for target in [*implied, name]:
                if target != source:
                    edges.add(Edge(source, target, str(path.relative_to(ROOT)), line))
    return sorted(edges, key=lambda e: (e.file, e.line, e.target))


EDGES = project_edges()


def wing(module: str) -> str:
    return max((w for w in WINGS if module == w or module.startswith(w + ".")), key=len)


def allowed(source: str, target: str) -> bool:
    a, b = wing(source), wing(target)
    return a == b or WINGS[b] < WINGS[a] or (a, b) in ALSO_ALLOWED


def cycles(edges: list[Edge]) -> list[list[Edge]]:
    """One cycle (as its edges) per strongly connected component of more than one module
    (Tarjan's algorithm, iterative)."""
    graph: dict[str, list[Edge]] = {}
    for edge in edges:
        graph.setdefault(edge.source, []).append(edge)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[set[str]] = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(graph.get(start, [])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            edge = next(children, None)
            if edge is not None:
                child = edge.target
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(graph.get(child, []))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.add(member)
                    if member == node:
                        break
                if len(component) > 1:
                    components.append(component)
    found = []
    for component in components:
        start = min(component)
        path = _path_back(graph, component, start)
        found.append(path)
    return found


def _path_back(graph: dict[str, list[Edge]], component: set[str], start: str) -> list[Edge]:
    """Edges of a shortest cycle through ``start`` inside ``component`` (breadth first)."""
    previous: dict[str, Edge] = {}
    frontier = [start]
    while frontier:
        following = []
        for node in frontier:
            for edge in graph.get(node, []):
                if edge.target not in component or edge.target in previous:
                    continue
                previous[edge.target] = edge
                if edge.target == start:
                    path, at = [], start
                    while True:
                        path.append(previous[at])
                        at = previous[at].source
                        if at == start:
                            return path[::-1]
                following.append(edge.target)
        frontier = following
    raise AssertionError(f"no cycle through {start}")


def test_the_walk_sees_the_project():
    """The checks below mean something only if the walk found the modules and their edges."""
    assert {"validation.cli", "validation.engines.mujoco.adapter", "mini_engine.step"} <= set(
        MODULES
    ), sorted(MODULES)
    assert any(e.source == "validation.cli" and e.target == "validation.jobs.run" for e in EDGES), (
        "validation.cli -> validation.jobs.run not found"
    )
    assert all(wing(m) in WINGS for m in MODULES)


def test_no_import_cycles():
    found = cycles(EDGES)
    shown = [" ; ".join(str(e) for e in cycle) for cycle in found]
    assert found == [], "import cycles:\n" + "\n".join(shown)


def test_no_upward_imports_between_wings():
    upward = [
        f"{edge} ({wing(edge.source)} rank {WINGS[wing(edge.source)]} imports "
        f"{wing(edge.target)} rank {WINGS[wing(edge.target)]})"
        for edge in EDGES
        if not allowed(edge.source, edge.target)
    ]
    assert upward == [], "upward imports:\n" + "\n".join(upward)


def test_mini_engine_imports_nothing_from_validation():
    found = [
        str(e)
        for e in EDGES
        if e.source.startswith("mini_engine") and wing(e.target) != "mini_engine"
    ]
    assert found == [], found


@pytest.mark.parametrize("engine", sorted(ENGINE_HOMES))
def test_each_engine_is_imported_only_by_its_adapter(engine):
    home = ENGINE_HOMES[engine]
    found = []
    for module, path in MODULES.items():
        relative = path.relative_to(ROOT).as_posix()
        if relative.startswith(home):
            continue
        for line, name in imported_names(module, ast.parse(path.read_text())):
            if name.split(".")[0].startswith(engine):
                found.append(f"{relative}:{line}: {name}")
    assert found == [], f"{engine} imported outside {home}:\n" + "\n".join(sorted(set(found)))


REFERENCE_SIDE = "validation.reference"
"""The closed forms the engines are judged against: they must not depend on the engine under
test, or a mistake in mini_engine would move its own reference."""


def import_chains(sources: list[str], edges: list[Edge]) -> dict[str, list[Edge]]:
    """Every module reachable from ``sources`` through ``edges``, with one shortest chain of
    edges that reaches it (breadth first)."""
    graph: dict[str, list[Edge]] = {}
    for edge in edges:
        graph.setdefault(edge.source, []).append(edge)
    chains: dict[str, list[Edge]] = {source: [] for source in sources}
    frontier = list(sources)
    while frontier:
        following = []
        for node in frontier:
            for edge in graph.get(node, []):
                if edge.target not in chains:
                    chains[edge.target] = [*chains[node], edge]
                    following.append(edge.target)
        frontier = following
    return chains


def test_the_reference_side_imports_nothing_from_mini_engine():
    """Neither directly nor through any project module it imports."""
    sources = [m for m in MODULES if wing(m) == REFERENCE_SIDE]
    assert f"{REFERENCE_SIDE}.newton_euler" in sources, sources
    chains = import_chains(sources, EDGES)
    found = [  # each way in: the chain up to its first mini_engine module
        " ; ".join(str(e) for e in chain)
        for module, chain in sorted(chains.items())
        if wing(module) == "mini_engine" and wing(chain[-1].source) != "mini_engine"
    ]
    assert found == [], "the reference side reaches mini_engine:\n" + "\n".join(found)


MEASUREMENT = "validation.measure"
"""What the engines' observed states are measured with (contacts, impacts, penetration, the
metrics): like the reference side, it must not depend on the engine under test, or a mistake
in mini_engine's narrow phase would move every engine's rows."""

RUN_THROUGH = "validation.engines"
"""The one way the measurement reaches an engine: the runner runs the adapters (the engine
under test among them) through their wing; every other way in is a dependency."""


def test_the_measurement_imports_nothing_from_mini_engine():
    """Neither directly nor through anything it imports, the scene side's compiled scene and
    shapes included, except by running the engines (``RUN_THROUGH``)."""
    sources = [m for m in MODULES if wing(m) == MEASUREMENT]
    assert f"{MEASUREMENT}.recording" in sources, sources
    measured = [
        e for e in EDGES if not (e.target.startswith(RUN_THROUGH) and wing(e.source) == MEASUREMENT)
    ]
    chains = import_chains(sources, measured)
    found = [
        " ; ".join(str(e) for e in chain)
        for module, chain in sorted(chains.items())
        if wing(module) == "mini_engine" and wing(chain[-1].source) != "mini_engine"
    ]
    assert found == [], "the measurement reaches mini_engine:\n" + "\n".join(found)
    assert any(e.target.startswith(RUN_THROUGH) for e in EDGES if wing(e.source) == MEASUREMENT)


def test_mini_engine_accepts_every_orientation_and_inertia_the_format_accepts():
    """The format's tolerances are its own (``scenario.schema``, which imports no engine); the
    engine's model builder must be no stricter, or a valid scene would fail to load in it."""
    import mini_engine.model as engine
    import validation.scenario.schema as schema

    assert engine.UNIT_QUATERNION_TOLERANCE >= schema.UNIT_QUATERNION_TOLERANCE
    assert engine.SYMMETRY_TOLERANCE >= schema.SYMMETRY_TOLERANCE


def test_importing_the_reference_side_loads_no_mini_engine_module():
    """The same at run time, in a fresh interpreter: every module of the reference side
    imported, then no ``mini_engine`` module is loaded (dynamic imports included)."""
    sources = sorted(m for m in MODULES if wing(m) == REFERENCE_SIDE)
    program = (
        "import importlib, sys\n"
        f"for name in {sources!r}:\n"
        "    importlib.import_module(name)\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'mini_engine'))\n"
    )
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, env=environment
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]", f"loaded with the reference side: {done.stdout.strip()}"


HEAVY_PACKAGES = ("mujoco", "pybullet", "pandas", "matplotlib", "scipy", "sqlalchemy", "jinja2")
"""Packages a light command must not import: the engines and what the report, the history
and the reference integration need (together most of a second and a half of import time)."""

LIGHT_COMMANDS = {
    "--help": ("pydantic", "numpy", "yaml", "mini_engine"),
    "--version": ("pydantic", "numpy", "yaml", "mini_engine"),
    "check": (),
    "list": (),
}
"""Command -> packages it must not import besides ``HEAVY_PACKAGES``: help and version read
nothing but argparse and package metadata; check and list load scene files (PyYAML,
pydantic, mini_engine's model for the overlap check) and nothing else."""


@pytest.mark.parametrize("command", sorted(LIGHT_COMMANDS))
def test_a_light_command_imports_only_what_it_uses(command, tmp_path):
    """``physval check FILE``, ``list``, ``--help`` and ``--version`` run in a fresh
    interpreter; the modules loaded by then exclude the engines (``HEAVY_PACKAGES``, every
    installed engine's ``requires`` and every ``validation.engines.<name>.adapter``), pandas,
    matplotlib and SciPy (each command imports what it uses when it runs)."""
    scene = ROOT / "scenarios" / "formulas" / "projectile.yaml"
    argv = {"check": ["check", str(scene)], "list": ["list", str(scene)]}.get(command, [command])
    program = (
        "import sys\n"
        "from validation.cli import main\n"
        "try:\n"
        f"    code = main({argv!r})\n"
        "except SystemExit as stop:\n"
        "    code = stop.code\n"
        "print(sorted(sys.modules), file=sys.stderr)\n"
        "sys.exit(code)\n"
    )
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", program],
        capture_output=True,
        text=True,
        env=environment,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    modules = set(ast.literal_eval(done.stderr.strip().splitlines()[-1]))
    loaded = {m.split(".")[0] for m in modules}
    forbidden = loaded & {*HEAVY_PACKAGES, *_engine_packages(), *LIGHT_COMMANDS[command]}
    forbidden |= {m for m in modules if re.fullmatch(ENGINE_ADAPTER_MODULE, m)}
    assert not forbidden, f"physval {command} imported {sorted(forbidden)}"


ENGINE_ADAPTER_MODULE = r"validation\.engines\.[A-Za-z0-9_]+\.adapter"
"""An engine adapter's module: it imports its engine (a declaration never does)."""


def _engine_packages() -> set[str]:
    """The top-level packages every installed engine's adapter may need (``requires``)."""
    from validation.engine_api import declarations

    return {m.split(".")[0] for d in declarations().values() for m in d.requires}


def test_the_baseline_actions_the_command_line_offers_are_the_ones_it_has():
    """``physval baseline ACTION`` offers the contract's names without importing the baseline
    module (pandas); each must be an action that module has."""
    from validation.contract import BASELINE_ACTION_NAMES
    from validation.nightly.baseline import BASELINE_ACTIONS

    assert tuple(BASELINE_ACTIONS) == BASELINE_ACTION_NAMES, (
        BASELINE_ACTIONS,
        BASELINE_ACTION_NAMES,
    )


def test_the_sabotage_module_imports_neither_numpy_nor_mini_engine():
    """Every command checks ``PHYSVAL_SABOTAGE`` before any work (``physval check`` too): in
    a fresh interpreter, importing the sabotage module and checking the variable loads no
    NumPy and no mini_engine module (they come when a sabotage is applied)."""
    program = (
        "import sys\n"
        "from validation.engines.sabotage import chosen\n"
        "chosen({'PHYSVAL_SABOTAGE': 'sphere_box_normal_flipped'})\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'mini_engine'}))\n"
    )
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, env=environment
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]", f"loaded with the sabotage module: {done.stdout.strip()}"
