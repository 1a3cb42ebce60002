"""The layers of the project, checked on the source (every import, lazy ones included):

    common          the shared vocabulary, payloads, ports, settings schema: imports no other
                    package of the project
    transport       the links: imports common, never agent
    agent           the agent; its logic (agent/node.py) imports no transport, the process
                    wiring (agent/process.py) and the config reader (agent/settings.py) do
    firmware_sim    simulators and emulated hardware
    hil             command line, launchers, tools

and no cycle between the packages, nor between the files (modules): a module never imports,
through any chain of imports (lazy ones and those for the type checker included), a module
that imports it.
"""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("common", "agent", "transport", "firmware_sim", "hil")


def imported_packages(path: Path, packages: tuple[str, ...] = PACKAGES) -> set[str]:
    """The project packages that the module at ``path`` imports."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:                    # relative: within the module's own package
                names = [path.parent.name]
            else:
                names = [node.module or ""]
        else:
            continue
        found |= {n.split(".")[0] for n in names} & set(packages)
    return found


def package_graph(root: Path, packages: tuple[str, ...] = PACKAGES) -> dict[str, set[str]]:
    """Package -> the other packages its modules import."""
    return {pkg: set().union(*(imported_packages(p, packages)
                               for p in sorted((root / pkg).rglob("*.py")))) - {pkg}
            for pkg in packages}


def module_graph(root: Path, packages: tuple[str, ...] = PACKAGES) -> dict[str, set[str]]:
    """Module (dotted name) -> the project modules it imports (``from package import
    module`` naming a module counts as importing it)."""
    files = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            files[".".join(parts)] = path
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        found = set()
        package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                found |= {alias.name for alias in node.names if alias.name in files}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[:len(package) - node.level + 1]
                                    + ([node.module] if node.module else []))
                for alias in node.names:
                    if f"{base}.{alias.name}" in files:
                        found.add(f"{base}.{alias.name}")
                    elif base in files:
                        found.add(base)
        graph[name] = found - {name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every cycle of ``graph``, each as a path that starts and ends at its least node."""
    found = []

    def walk(start: str, node: str, path: list[str]) -> None:
        for nxt in sorted(graph.get(node, ())):
            if nxt == start:
                found.append(path + [start])
            elif nxt > start and nxt not in path:
                walk(start, nxt, path + [nxt])

    for start in sorted(graph):
        walk(start, start, [start])
    return found


def violations(root: Path) -> list[str]:
    """What breaks the layering in the source tree at ``root``."""
    graph = package_graph(root)
    out = [f"common imports {', '.join(sorted(graph['common']))}"] if graph["common"] else []
    if "agent" in graph["transport"]:
        out.append("transport imports agent")
    if "transport" in imported_packages(root / "agent" / "node.py"):
        out.append("agent/node.py imports transport")
    out += ["package cycle " + " -> ".join(c) for c in cycles(graph)]
    out += ["module cycle " + " -> ".join(c) for c in cycles(module_graph(root))]
    return out


def test_the_source_tree_keeps_its_layers():
    assert violations(ROOT) == []


@pytest.mark.parametrize("module, forbidden", [
    ("agent.node", ("transport", "firmware_sim", "hil")),         # testable without links
    ("transport.mavlink_link", ("agent", "firmware_sim", "hil")),  # testable without agent
    ("transport.zenoh_link", ("agent", "firmware_sim", "hil")),
    ("transport.wheel_drivers", ("agent", "firmware_sim", "hil")),
    ("common.ports", ("agent", "transport", "firmware_sim", "hil")),
    ("common.schema", ("agent", "transport", "firmware_sim", "hil")),
])
def test_loading_a_module_loads_no_higher_layer(module, forbidden):
    """At run time too (what the module's imports load in turn, in a fresh interpreter)."""
    code = (f"import sys, {module}; print(sorted({{m.split('.')[0] for m in sys.modules}} "
            f"& {set(forbidden)!r}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def _tree(tmp_path: Path, modules: dict[str, str]) -> Path:
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "agent" / "node.py").write_text("")
    for name, text in modules.items():
        (tmp_path / name).write_text(text)
    return tmp_path


def test_the_check_sees_each_kind_of_violation(tmp_path):
    root = _tree(tmp_path, {
        "common/leak.py": "from agent.config import ControlParams\n",
        "transport/link.py": "def f():\n    import agent.node\n",        # lazy import
        "agent/node.py": "from transport import canbus\n",
        "firmware_sim/sim.py": "import hil.cli\n",
        "hil/cli.py": "from firmware_sim import sim\n",
    })
    assert violations(root) == [
        "common imports agent", "transport imports agent", "agent/node.py imports transport",
        "package cycle agent -> transport -> agent",
        "package cycle firmware_sim -> hil -> firmware_sim",
        "module cycle firmware_sim.sim -> hil.cli -> firmware_sim.sim"]


def test_a_cycle_between_two_files_of_one_package_is_seen(tmp_path):
    """agent/config.py and agent/law.py importing each other (config lazily, for a
    function, law for its parameters' type only): a cycle of files."""
    root = _tree(tmp_path, {
        "agent/config.py": "def f():\n    from agent.law import step\n",
        "agent/law.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                        "    from agent import config\n",
    })
    assert violations(root) == ["module cycle agent.config -> agent.law -> agent.config"]


def test_allowed_imports_pass(tmp_path):
    root = _tree(tmp_path, {
        "transport/link.py": "from common.payloads import StateMsg\n",
        "agent/process.py": "from transport import canbus\nfrom . import node\n",
        "hil/cli.py": "import agent.process, firmware_sim, transport.canbus, common\n",
    })
    assert violations(root) == []
