"""The package layout of STYLE.md: dependencies point one way and no two modules import each other.

Every ``import`` counts, including those under ``if TYPE_CHECKING:`` and inside functions: a
cycle hidden behind a late import is still two modules that cannot be understood apart.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from tests.helpers import ROOT


PACKAGE = ROOT / "simbridge"
#: The front ends: each translates its own wire to the graph's calls and back.
FRONT_ENDS = ("simbridge.rosbridge", "simbridge.ros2", "simbridge.foxglove", "simbridge.web")
#: The sans-I/O cores and what each may not import (STYLE.md: front ends and app -> robot ->
#: graph -> (msgs, sim)).
CORES = {
    "simbridge.sim": ("simbridge.graph", "simbridge.robot", "simbridge.msgs", *FRONT_ENDS),
    "simbridge.msgs": ("simbridge.graph", "simbridge.robot", "simbridge.sim", *FRONT_ENDS),
    "simbridge.graph": ("simbridge.robot", "simbridge.sim", *FRONT_ENDS),
    # the robot world's nodes: on the graph's API like any front end, beside none of them
    "simbridge.robot": FRONT_ENDS,
    # the grader: a node on the graph with its pure parts (tasks, metrics, results, report)
    "simbridge.grading": FRONT_ENDS,
}
#: The sans-I/O cores import no server, no loop, no composition root.
SHELL = (
    "asyncio",
    "websockets",
    "simbridge.app.build",
    "simbridge.app.steps",
    "simbridge.app.runner",
    "simbridge.app.guard",
    "simbridge.cli",
    "simbridge.tools",
    "simbridge.headless",
)
#: A front end's imports of another front end, each with why (none today: the rosbridge port
#: answers plain HTTP with the page's answers through a handler the composition root hands it,
#: typed with websockets' own request and response).
CROSSINGS_NOT_YET: set[tuple[str, str]] = set()


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in PACKAGE.rglob("*.py")}


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Modules of simbridge (and others, by top name) that ``path`` imports anywhere."""
    return _imports_text(name, path, path.read_text(), known)


def _imports_text(name: str, path: Path, text: str, known: set[str] | None = None) -> set[str]:
    """Modules that the source ``text`` of module ``name`` (at ``path``) imports anywhere."""
    known = known if known is not None else set(_modules())
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{anchor}.{base}" if base else anchor
            found.add(base)
            # `from simbridge.rosbridge import ops` imports the module simbridge.rosbridge.ops
            found.update(f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in known)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    known = set(modules)
    return {
        name: {m for m in _imports(name, path, known) if m in known and m != name}
        for name, path in modules.items()
    }


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
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
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_two_modules_import_each_other() -> None:
    """No import cycle, counting TYPE_CHECKING and function-level imports."""
    assert _cycles(_graph()) == []


def test_the_cycle_check_finds_a_cycle() -> None:
    """The check itself can fail: a made-up a -> b -> c -> a is reported."""
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_cores_import_no_shell_and_point_one_way() -> None:
    """The cores import no asyncio, websockets, server, web or tools, and point one way."""
    modules = _modules()
    known = set(modules)
    wrong = []
    for name, path in modules.items():
        core = next((c for c in CORES if name == c or name.startswith(c + ".")), None)
        if core is None:
            continue
        for imported in _imports(name, path, known):
            banned = (*SHELL, *CORES[core])
            if any(imported == b or imported.startswith(b + ".") for b in banned):
                wrong.append(f"{name} imports {imported}")
    assert wrong == []


#: The settings framework: pydantic and the modules that declare settings on it.
SETTINGS_FRAMEWORK = (
    "pydantic",
    "pydantic_core",
    "pydantic_settings",
    "simbridge.schema",
    "simbridge.app.settings",
    "simbridge.app.config",
)
#: Cores that take plain parameters (STYLE.md: "numpy only, plain parameters").
PLAIN_CORES = ("simbridge.graph", "simbridge.msgs", "simbridge.sim")


def test_the_cores_import_no_settings_framework() -> None:
    """graph, msgs and sim take plain parameters: no pydantic, no settings, not even lazily."""
    modules = _modules()
    known = set(modules)
    wrong = {
        name
        for name, path in modules.items()
        if any(name == c or name.startswith(c + ".") for c in PLAIN_CORES)
        for imported in _imports(name, path, known)
        if any(imported == b or imported.startswith(b + ".") for b in SETTINGS_FRAMEWORK)
    }
    assert not wrong, wrong


def test_no_front_end_imports_another() -> None:
    """rosbridge, ROS 2 (Zenoh, DDS), Foxglove and the page each reach the graph on their own.

    None pretends to be another: no module of one imports a module of another (lazily and
    under TYPE_CHECKING too), but for the crossings listed by name with why.
    """
    modules = _modules()
    known = set(modules)
    imports = {name: _imports(name, path, known) for name, path in modules.items()}
    assert _crossings(imports) == CROSSINGS_NOT_YET


def _front_end(name: str) -> str | None:
    return next((f for f in FRONT_ENDS if name == f or name.startswith(f + ".")), None)


def _crossings(imports: dict[str, set[str]]) -> set[tuple[str, str]]:
    """The (module, imported) pairs of ``imports`` where one front end imports another."""
    return {
        (name, imported)
        for name, imported_all in imports.items()
        if (mine := _front_end(name)) is not None
        for imported in imported_all
        if _front_end(imported) not in (None, mine)
    }


def test_the_front_end_check_finds_a_crossing() -> None:
    """The check itself can fail: the Zenoh link once sent its calls as rosbridge ops.

    And the rosbridge server once took the page's request and answer types.
    """
    path = PACKAGE / "ros2" / "zenoh" / "link.py"
    text = "from simbridge.rosbridge.front import Rosbridge\n"
    tree_imports = {m for m in _imports_text("simbridge.ros2.zenoh.link", path, text)}
    assert "simbridge.rosbridge.front" in tree_imports
    server = PACKAGE / "rosbridge" / "server.py"
    lazy = "def f():\n    from simbridge.web import WebApp\n"
    found = _imports_text("simbridge.rosbridge.server", server, lazy)
    assert _crossings(
        {"simbridge.rosbridge.server": found, "simbridge.ros2.zenoh.link": tree_imports}
    ) == {
        ("simbridge.rosbridge.server", "simbridge.web"),
        ("simbridge.ros2.zenoh.link", "simbridge.rosbridge.front"),
    }


def test_the_server_does_not_import_the_tools() -> None:
    """Nothing outside simbridge.tools imports them but the CLI and the composition root.

    The tools sit on top; simbridge.app.build makes the recorder of --record and the grader's
    run bags for the server.
    """
    graph = _graph()
    users = sorted(
        name
        for name, imported in graph.items()
        if not name.startswith("simbridge.tools")
        and name not in ("simbridge.cli", "simbridge.app.build")
        and any(m.startswith("simbridge.tools") for m in imported)
    )
    assert users == []


def test_top_level_holds_the_parts_and_the_entry_points() -> None:
    """The top level of the package: the parts, and a handful of modules that join them."""
    top = sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem not in ("__init__", "__main__"))
    packages = sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))
    assert packages == [
        "app",
        "foxglove",
        "grading",
        "graph",
        "msgs",
        "robot",
        "ros2",
        "rosbridge",
        "sim",
        "tools",
        "web",
    ]
    assert top == ["cli", "errors", "headless"]


def test_every_package_imports_first_on_its_own() -> None:
    """Each package imported first in a fresh set of modules: no cycle through a package init.

    Importing ``simbridge.graph.access`` runs ``simbridge/graph/__init__.py`` too; a cycle
    through package inits passes the module check above and fails only for the entry point that
    imports in that order (``--certfile``, importing the rosbridge server first, once did).
    """
    names = sorted(_module_name(p) for p in PACKAGE.glob("*/__init__.py"))
    script = (
        "import importlib, sys\n"
        "failed = []\n"
        f"for name in {names!r}:\n"
        "    for m in [m for m in sys.modules if m.startswith('simbridge')]:\n"
        "        del sys.modules[m]\n"
        "    try:\n"
        "        importlib.import_module(name)\n"
        "    except ImportError as err:\n"
        "        if 'simbridge' in (err.name or '') or 'partially initialized' in str(err):\n"
        "            failed.append(f'{name}: {err}')\n"
        "print('\\n'.join(failed))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert done.stdout.strip() == ""
