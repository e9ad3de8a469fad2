"""The house: the contract floor at the bottom, imports only downward, no private names
across modules (issue 34).

Layers, top to bottom: apps (report, demo) -> predictor -> surrogate -> workflow (data) -> fem,
all on contract.
The checks read every module's import statements (ast, so imports inside functions count
too) and import the dolfinx-free layers in a fresh interpreter.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The project packages each package may import (itself included).
ALLOWED = {
    "contract": {"contract"},
    "fem": {"contract", "fem"},
    "workflow": {"contract", "fem", "workflow"},
    "surrogate": {"contract", "workflow", "surrogate"},
    "predictor": {"contract", "fem", "workflow", "surrogate", "predictor"},
    "apps": {"contract", "fem", "workflow", "surrogate", "predictor", "apps"},
}
#: Third-party packages the contract floor may import.
CONTRACT_THIRD_PARTY = {"numpy"}


def _modules():
    for package in ALLOWED:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield package, path


def _imports(path: Path):
    """(module imported, names imported from it) for every import statement in ``path``."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, []
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module, [a.name for a in node.names]


@pytest.mark.parametrize("package,path", list(_modules()), ids=lambda v: getattr(v, "name", v))
def test_imports_run_downward_and_name_no_private_names(package, path):
    for module, names in _imports(path):
        top = module.split(".")[0]
        if top in ALLOWED:
            assert top in ALLOWED[package], f"{path.relative_to(ROOT)} imports {module} (upward)"
            private = [n for n in names if n.startswith("_") and n != "__version__"]
            assert not private, f"{path.relative_to(ROOT)} imports private {private} from {module}"
        elif package == "contract":
            stdlib = top in sys.stdlib_module_names or top == "__future__"
            assert stdlib or top in CONTRACT_THIRD_PARTY, f"contract imports {module}"


def test_the_dolfinx_free_layers_import_no_dolfinx_and_contract_no_torch():
    """Every module of contract, surrogate, predictor and apps imported (command lines too):
    dolfinx is never loaded, and the contract loads neither torch nor gmsh."""
    code = """
import importlib, pkgutil, sys
for pkg in ("contract",):
    for m in pkgutil.iter_modules([pkg]):
        importlib.import_module(f"{pkg}.{m.name}")
light = sorted(m for m in ("torch", "dolfinx", "gmsh") if m in sys.modules)
for pkg in ("surrogate", "predictor", "apps"):
    for m in pkgutil.iter_modules([pkg]):
        importlib.import_module(f"{pkg}.{m.name}")
print(light, "dolfinx" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["[]", "False"], out.stdout
