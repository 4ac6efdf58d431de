"""The house rules, checked: no import circle, no dispatch on concrete system types
outside the systems' own packages, no side effects on import, a short README."""

import ast
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "lagjax"
SYSTEM_TYPES = {
    "Lagrangian",
    "AbstractHamiltonian",
    "Hamiltonian",
    "SeparableHamiltonian",
    "LegendreHamiltonian",
    "RigidBody",
    "AbstractScene",
}
SYSTEM_PACKAGES = {"mechanics", "rigid", "scenes"}


def _modules() -> dict[str, Path]:
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


def _imported(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Every lagjax module `module` imports, wherever the import statement is."""
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            names = [base] + [f"{base}.{alias.name}" for alias in node.names]
        for name in names:
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name.startswith("lagjax") and name != module:
                found.add(name)
    return found


def test_the_import_graph_has_no_circle():
    modules = _modules()
    graph = {m: _imported(m, p, modules) for m, p in modules.items()}
    state: dict[str, int] = {}  # 1 on the current path, 2 finished

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for other in sorted(graph[module]):
            if state.get(other) == 1:
                circle = [*path[path.index(other) :], other]
                raise AssertionError("import circle: " + " -> ".join(circle))
            if other not in state:
                visit(other, [*path, other])
        state[module] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])


def test_no_dispatch_on_system_types_outside_the_systems():
    offenders = []
    for module, path in _modules().items():
        if module.split(".")[1:2] and module.split(".")[1] in SYSTEM_PACKAGES:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if not (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name)
                and node.func.id in {"isinstance", "issubclass"}
                and len(node.args) == 2
            ):
                continue
            named = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
            if named & SYSTEM_TYPES:
                offenders.append(f"{module}:{node.lineno}")
    assert not offenders, offenders


def test_few_modules_at_the_top_of_the_package():
    top = [p.name for p in PACKAGE.glob("*.py")]
    assert len(top) <= 15, top


def test_importing_lagjax_and_its_command_changes_nothing_in_the_process():
    code = (
        "import os, jax\n"
        "before = (os.environ.get('XLA_FLAGS'), jax.config.jax_enable_x64)\n"
        "import lagjax, lagjax.cli, lagjax.cli.demo\n"
        "after = (os.environ.get('XLA_FLAGS'), jax.config.jax_enable_x64)\n"
        "assert before == after, (before, after)\n"
        "print('unchanged', after)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert "unchanged (None, False)" in done.stdout


def test_the_readme_is_short_and_says_how_to_install():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 200
    assert "pip install" in readme
    assert "issue" not in readme.lower()
    assert "../shared" not in readme
