"""The house: the contract floor at the bottom, imports only downward, no private names
across modules (issue 34).

Layers, top to bottom: apps (report, demo) -> predictor -> surrogate -> workflow (data) -> fem,
all on contract. Inside fem (issue 61), its sub-packages, bottom to top: mesh -> physics ->
solvers (the library) -> cli -> studies; each imports only those below it and itself, so the
library never imports a command line or a study; fem's root holds neutral modules (the
studies' formats ``fem.artefacts``, the shared options ``fem.options``) and aliases. Nothing
outside fem.cli and fem.studies imports them (apps run them as subprocesses). Inside
predictor likewise: model -> solvers -> nn -> planning -> calibration -> validation -> cli,
with ``api`` (the front door), the neutral ``defaults`` and ``artefacts`` and the old command
paths (aliases) at its root. Neither package's modules import each other in a circle
(docs/packages.md).
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
#: fem's sub-packages, bottom to top: each may import itself and those before it.
FEM_FLOORS = ("mesh", "physics", "solvers", "cli", "studies")
#: The modules at fem's root: the package file (imports nothing) and the old command paths,
#: thin aliases that run fem.cli's commands (README, changes).
FEM_ROOT = {"__init__": (), "finger": ("cli",), "solve": ("cli",), "artefacts": (), "options": ("mesh",)}
#: fem's neutral root modules (no dolfinx) and the lowest sub-package that may import each:
#: the studies' JSON formats (imported by predictor and apps too), the command-line options
#: shared by fem.cli, fem.studies and workflow's commands (built on fem.mesh's value objects).
FEM_NEUTRAL = {"artefacts": "mesh", "options": "physics"}
#: The fem modules that load no dolfinx, gmsh or MPI (value objects, options, formats).
FEM_LIGHT = ("fem.mesh.geometry", "fem.mesh.discretisation", "fem.mesh.data", "fem.options",
             "fem.artefacts", "fem.studies.elastica")
#: predictor's sub-packages, bottom to top: each may import itself and those before it.
PRED_FLOORS = ("model", "solvers", "nn", "planning", "calibration", "validation", "cli")
#: predictor's neutral root modules: import no predictor module, any module may import them.
PRED_NEUTRAL = ("defaults", "artefacts")
#: The other modules at predictor's root and what each may import: the package file (the
#: API, lazily), the API (every sub-package but the command lines), the old command paths
#: (aliases that run the command where it moved; README, changes).
PRED_ROOT = {"__init__": ("api",), "api": PRED_FLOORS[:-1],
             **dict.fromkeys(("gesture", "inverse", "atlas", "calibrate", "figures"), ("cli",)),
             **dict.fromkeys(("validate_finger", "validate_grasps", "bench", "contact_change"), ("validation",))}
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
    for m in pkgutil.walk_packages([pkg], prefix=f"{pkg}."):
        importlib.import_module(m.name)
print(light, "dolfinx" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["[]", "False"], out.stdout


def _fem_floor(module: str) -> str | None:
    """The fem sub-package of an imported module name ("fem.physics.problem" -> "physics"),
    None outside fem; "fem" alone is the root."""
    parts = module.split(".")
    if parts[0] != "fem":
        return None
    return parts[1] if len(parts) > 1 else "fem"


def fem_import_error(importer: str, module: str, names=()) -> str | None:
    """Why ``importer`` (a path under fem/, e.g. "fem/solvers/joint.py") may not import
    ``module`` (with ``names`` from it), or None when it may: sub-packages import only their
    own and those below them (FEM_FLOORS); the root's aliases only fem.cli."""
    floor = _fem_floor(module)
    if floor is None:
        return None
    if floor == "fem":    # ``from fem import physics``: the sub-packages named
        return next(filter(None, (fem_import_error(importer, f"fem.{n}") for n in names)), None)
    parts = Path(importer).parts
    if floor in FEM_NEUTRAL:
        lowest = FEM_NEUTRAL[floor]
        if len(parts) == 2 or FEM_FLOORS.index(parts[1]) >= FEM_FLOORS.index(lowest):
            return None
        return f"{importer} imports {module}: only fem.{lowest} and above may"
    if floor not in FEM_FLOORS:
        return f"{importer} imports {module}: not a module of a fem sub-package {FEM_FLOORS}"
    if len(parts) == 2:   # fem/finger.py
        allowed = FEM_ROOT.get(Path(importer).stem, ())
        return None if floor in allowed else f"{importer} (an alias) imports {module}"
    own = parts[1]
    if FEM_FLOORS.index(floor) > FEM_FLOORS.index(own):
        return f"{importer} imports {module}: fem.{own} may not import fem.{floor} (upward)"
    return None


def _fem_modules():
    return sorted((ROOT / "fem").rglob("*.py"))


def test_fem_is_its_sub_packages_and_their_package_files_import_nothing():
    root = {p.stem for p in (ROOT / "fem").glob("*.py")}
    assert root <= set(FEM_ROOT), f"modules at fem's root: {sorted(root - set(FEM_ROOT))}; they belong in {FEM_FLOORS}"
    folders = {p.parent.name for p in (ROOT / "fem").glob("*/*.py")}
    assert folders == set(FEM_FLOORS), folders
    for sub in FEM_FLOORS:
        init = ROOT / "fem" / sub / "__init__.py"
        tree = ast.parse(init.read_text())
        assert ast.get_docstring(tree), f"{init} says what it holds and what it may import"
        assert "Imports:" in ast.get_docstring(tree), f"{init}: its docstring names what it may import"
        assert not list(_imports(init)), f"{init} imports (package files stay import-free: pyvista before dolfinx)"
    assert not list(_imports(ROOT / "fem" / "__init__.py"))


@pytest.mark.parametrize("path", _fem_modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_fem_sub_packages_import_downward(path):
    rel = str(path.relative_to(ROOT))
    for node in ast.walk(ast.parse(path.read_text(), rel)):
        assert not (isinstance(node, ast.ImportFrom) and node.level), f"{rel}: a relative import"
    errors = [e for module, names in _imports(path) if (e := fem_import_error(rel, module, names))]
    assert not errors, "\n".join(errors)


def test_the_checker_refuses_upward_imports():
    """The rule above, on imports nobody has written (yet)."""
    assert fem_import_error("fem/solvers/joint.py", "fem.studies.artefacts") is not None
    assert fem_import_error("fem/physics/problem.py", "fem.solvers.load_path") is not None
    assert fem_import_error("fem/mesh/build.py", "fem.cli.options") is not None
    assert fem_import_error("fem/cli/solve.py", "fem.studies.joint_cases") is not None
    assert fem_import_error("fem/solvers/grasp.py", "fem", ["cli"]) is not None
    assert fem_import_error("fem/solvers/grasp.py", "fem.finger") is not None       # an alias, not a module
    assert fem_import_error("fem/solve.py", "fem.solvers.joint") is not None        # aliases run fem.cli only
    assert fem_import_error("fem/studies/mesh_study.py", "fem.solvers.joint") is None
    assert fem_import_error("fem/solvers/joint.py", "fem.solvers.load_path") is None
    assert fem_import_error("fem/solvers/joint.py", "dolfinx.fem") is None
    assert fem_import_error("fem/studies/finger_grid.py", "fem.artefacts") is None
    assert fem_import_error("fem/mesh/build.py", "fem.artefacts") is None
    assert fem_import_error("fem/mesh/build.py", "fem.options") is not None     # options is built on fem.mesh
    assert fem_import_error("fem/cli/solve.py", "fem", ["options"]) is None


def _graph(package: str) -> dict[str, set[str]]:
    """module of ``package`` -> the modules of it that it imports (anywhere in the file)."""
    modules = {".".join(p.relative_to(ROOT).with_suffix("").parts): p for p in sorted((ROOT / package).rglob("*.py"))}
    graph = {}
    for name, path in modules.items():
        graph[name] = set()
        for module, names in _imports(path):
            for target in (module, *(f"{module}.{n}" for n in names)):
                if target in modules and target != name and not target.endswith("__init__"):
                    graph[name].add(target)
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_fem_modules_import_each_other_in_a_circle():
    graph = _graph("fem")
    assert "fem.physics.problem" in graph["fem.solvers.load_path"]      # the graph is read
    assert circles(graph) == []
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_fem_value_modules_load_no_dolfinx():
    code = f"import sys\nfor m in {FEM_LIGHT!r}: __import__(m)\n" \
           "print(sorted(m for m in ('dolfinx', 'gmsh', 'mpi4py', 'ufl') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["[]"], out.stdout


def test_nothing_outside_fem_cli_and_studies_imports_them():
    """A command line or a study is run, never imported, by the library and the other
    packages (issue 61): their formats are fem.artefacts, their options fem.options. fem's
    root aliases run fem.cli; tests may import anything."""
    aliases = {f"fem/{m}.py" for m, allowed in FEM_ROOT.items() if "cli" in allowed}
    errors = []
    for package, path in _modules():
        rel = str(path.relative_to(ROOT))
        if rel.startswith(("fem/cli/", "fem/studies/")) or rel in aliases:
            continue
        for module, names in _imports(path):
            targets = [module] + [f"{module}.{n}" for n in names if module == "fem"]
            errors += [f"{rel} imports {t}" for t in targets if t.startswith(("fem.cli", "fem.studies"))]
    assert errors == []


def _commands(package: str) -> dict[str, Path]:
    """The command lines of ``package`` (a ``main`` run by a ``__main__`` guard), by module
    name, its root aliases (modules of one statement, the guard that runs a moved command)
    left out."""
    out = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        text = path.read_text()
        if "def main(" in text and 'if __name__ == "__main__":' in text:
            out[".".join(path.relative_to(ROOT).with_suffix("").parts)] = path
    return out


def _commands_imported(source: str, commands) -> list[str]:
    """The modules of ``commands`` that the Python ``source`` imports (inside functions too):
    ``import a.b``, ``from a.b import x`` and ``from a import b`` alike."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name in commands]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found += [t for t in [node.module] + [f"{node.module}.{a.name}" for a in node.names] if t in commands]
    return found


@pytest.mark.parametrize("package", ["fem", "predictor"])
def test_no_module_imports_a_command_or_a_study(package):
    """Issue 61's target: inside fem and predictor no module imports a command line or a
    study (a module with a ``main``): what two commands share lives in a module without one
    (fem.studies.joint_cases, fem.studies.finger_records, predictor.validation.cases). Only
    the old command paths at the package root import the command they run."""
    commands = _commands(package)
    assert len(commands) >= 10, commands
    aliases = {p for p in (ROOT / package).glob("*.py") if len(ast.parse(p.read_text()).body) <= 2}
    errors = [f"{path.relative_to(ROOT)} imports {c}" for path in sorted((ROOT / package).rglob("*.py"))
              if path not in aliases for c in _commands_imported(path.read_text(), commands)]
    assert errors == []


def test_the_command_import_check_finds_a_study_importing_a_study():
    """The check above sees both spellings, ``from fem.studies import finger_cases`` and
    ``import fem.studies.finger_cases``, and knows the studies and command lines."""
    fem, pred = _commands("fem"), _commands("predictor")
    assert {"fem.studies.finger_cases", "fem.studies.mesh_study", "fem.cli.finger"} <= set(fem)
    assert "fem.studies.finger_records" not in fem and "fem.studies.joint_cases" not in fem
    assert {"predictor.cli.atlas", "predictor.validation.finger"} <= set(pred)
    assert "predictor.planning.atlas" not in pred and "predictor.validation.cases" not in pred
    for code in ("from fem.studies import finger_cases", "import fem.studies.finger_cases as fc",
                 "def f():\n    from fem.studies.finger_cases import CASES"):
        assert _commands_imported(code, fem) == ["fem.studies.finger_cases"], code
    assert _commands_imported("from fem.studies.finger_records import CASES", fem) == []
    assert _commands_imported("from predictor.cli.atlas import main", pred) == ["predictor.cli.atlas"]


def _pred_floor(module: str) -> str | None:
    """The predictor sub-package or root module of an imported module name
    ("predictor.solvers.lm" -> "solvers", "predictor.api" -> "api"), "predictor" alone for
    the package, None outside predictor."""
    parts = module.split(".")
    if parts[0] != "predictor":
        return None
    return parts[1] if len(parts) > 1 else "predictor"


def predictor_import_error(importer: str, module: str, names=()) -> str | None:
    """Why ``importer`` (a path under predictor/) may not import ``module``, or None when it
    may: sub-packages import their own and those below them (PRED_FLOORS) and the neutral
    root modules; the API every sub-package but cli; an alias at the root only the command
    it runs; nobody imports an alias."""
    floor = _pred_floor(module)
    if floor is None:
        return None
    if floor == "predictor":   # ``from predictor import api``
        return next(filter(None, (predictor_import_error(importer, f"predictor.{n}") for n in names)), None)
    if floor in PRED_NEUTRAL:
        return None
    parts = Path(importer).parts
    if len(parts) == 2:
        allowed = PRED_ROOT.get(Path(importer).stem, ())
        return None if floor in allowed else f"{importer} imports {module} (allowed: {allowed})"
    if floor not in PRED_FLOORS:
        return f"{importer} imports {module}: not a module of a predictor sub-package {PRED_FLOORS}"
    own = parts[1]
    if PRED_FLOORS.index(floor) > PRED_FLOORS.index(own):
        return f"{importer} imports {module}: predictor.{own} may not import predictor.{floor} (upward)"
    return None


def test_predictor_is_its_sub_packages_and_their_package_files_import_nothing():
    root = {p.stem for p in (ROOT / "predictor").glob("*.py")}
    assert root == set(PRED_ROOT) | set(PRED_NEUTRAL), sorted(root ^ (set(PRED_ROOT) | set(PRED_NEUTRAL)))
    folders = {p.parent.name for p in (ROOT / "predictor").glob("*/*.py")}
    assert folders == set(PRED_FLOORS), folders
    for sub in PRED_FLOORS:
        init = ROOT / "predictor" / sub / "__init__.py"
        doc = ast.get_docstring(ast.parse(init.read_text()))
        assert doc and "Imports:" in doc, f"{init} says what it holds and what it may import"
        assert not list(_imports(init)), f"{init} imports (package files stay import-free)"


@pytest.mark.parametrize("path", sorted((ROOT / "predictor").rglob("*.py")), ids=lambda p: str(p.relative_to(ROOT)))
def test_predictor_sub_packages_import_downward(path):
    rel = str(path.relative_to(ROOT))
    for node in ast.walk(ast.parse(path.read_text(), rel)):
        assert not (isinstance(node, ast.ImportFrom) and node.level), f"{rel}: a relative import"
    errors = [e for module, names in _imports(path) if (e := predictor_import_error(rel, module, names))]
    assert not errors, "\n".join(errors)


def test_the_predictor_checker_refuses_upward_imports():
    assert predictor_import_error("predictor/model/statics.py", "predictor.solvers.solve") is not None
    assert predictor_import_error("predictor/solvers/ramp.py", "predictor.planning.atlas") is not None
    assert predictor_import_error("predictor/planning/atlas.py", "predictor.cli.gesture") is not None
    assert predictor_import_error("predictor/planning/atlas.py", "predictor.api") is not None
    assert predictor_import_error("predictor/cli/gesture.py", "predictor.gesture") is not None   # an alias
    assert predictor_import_error("predictor/api.py", "predictor.cli.atlas") is not None
    assert predictor_import_error("predictor/nn/train.py", "predictor", ["cli"]) is not None
    assert predictor_import_error("predictor/gesture.py", "predictor.solvers.solve") is not None  # aliases run a command
    assert predictor_import_error("predictor/nn/__main__.py", "predictor.cli.nn") is not None  # runs it (runpy)
    assert predictor_import_error("predictor/nn/train.py", "predictor.solvers", ["progress"]) is None
    assert predictor_import_error("predictor/model/joint.py", "predictor.defaults") is None
    assert predictor_import_error("predictor/cli/inverse.py", "predictor.planning.inversion") is None


def test_no_predictor_modules_import_each_other_in_a_circle():
    graph = _graph("predictor")
    assert "predictor.model.statics" in graph["predictor.solvers.solve"]      # the graph is read
    assert circles(graph) == []
