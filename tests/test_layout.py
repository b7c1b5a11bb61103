"""The package's layering (docs/layout.md): lawn_cli -> paper -> training -> evaluation -> agents ->
lawn_env at run time (imports for annotations only, under ``if TYPE_CHECKING:``, aside), no import cycles between modules of any
kind (function-level and annotation-only imports included), no module importing another's private
names, and every public function annotated."""

import ast
import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: The packages, lowest first: each imports only those before it (and itself).
PACKAGES = ("lawn_env", "agents", "evaluation", "training", "paper", "lawn_cli")
#: The products apart from the simulator and the policies: small modules, imports at the top.
PRODUCTS = ("evaluation", "training", "paper", "lawn_cli")


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for f in (ROOT / pkg).rglob("*.py"):
            name = ".".join(f.relative_to(ROOT).with_suffix("").parts)
            mods[name.removesuffix(".__init__")] = f
    return mods


def _runtime_nodes(tree: ast.Module, annotations: bool = False, module_level: bool = False):
    """Every node except, unless ``annotations``, those under ``if TYPE_CHECKING:`` (imports for
    annotations only), and with ``module_level`` those inside functions (what runs only when called)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if (not annotations and isinstance(child, ast.If) and isinstance(child.test, ast.Name)
                    and child.test.id == "TYPE_CHECKING"):
                stack.extend(child.orelse)
                continue
            if module_level and isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            stack.append(child)


def _imports(mods: dict[str, Path], annotations: bool = False, module_level: bool = False):
    """module -> set of modules it imports at run time (with ``annotations``: also those it imports
    for annotations only; with ``module_level``: only those it imports when it is imported, not in its
    functions), and the (module, from, name) private imports."""
    edges, private = {m: set() for m in mods}, []
    for m, f in mods.items():
        package = m.split(".") if f.name == "__init__.py" else m.split(".")[:-1]
        for node in _runtime_nodes(ast.parse(f.read_text()), annotations, module_level):
            if isinstance(node, ast.ImportFrom):
                target = node.module
                if node.level:
                    target = ".".join(package[: len(package) - node.level + 1] + ([node.module] if node.module else []))
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    hit = sub if sub in mods else target
                    if hit in mods and hit != m:
                        edges[m].add(hit)
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        private.append((m, target, alias.name))
            elif isinstance(node, ast.Import):
                edges[m].update(a.name for a in node.names if a.name in mods and a.name != m)
    return edges, private


def _cycles(edges: dict[str, set]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    return out


EDGES, PRIVATE = _imports(_modules())
ALL_EDGES, _ = _imports(_modules(), annotations=True)
MODULE_EDGES, _ = _imports(_modules(), module_level=True)


def test_no_import_cycles_of_any_kind():
    assert _cycles(ALL_EDGES) == []


def test_no_private_names_imported_across_modules():
    assert PRIVATE == []


@pytest.mark.parametrize("package", PACKAGES)
def test_layers_point_down(package):
    rank = {p: i for i, p in enumerate(PACKAGES)}
    bad = [(m, t) for m, ts in EDGES.items() if m.split(".")[0] == package for t in ts
           if rank[t.split(".")[0]] > rank[package]]
    assert bad == []


def test_the_checker_sees_cycles_private_imports_and_skips_annotation_imports(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import thing\n")
    (pkg / "b.py").write_text("def f():\n    from . import c\n")  # a function-level import counts
    (pkg / "c.py").write_text("from pkg.a import _hidden\n")
    (pkg / "d.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import x\n")
    (pkg / "e.py").write_text("from .d import y\n")
    mods = {f"pkg.{f.stem}" if f.stem != "__init__" else "pkg": f for f in pkg.glob("*.py")}
    edges, private = _imports(mods)
    assert _cycles(edges) == [["pkg.a", "pkg.b", "pkg.c"]]
    assert private == [("pkg.c", "pkg.a", "_hidden")]
    assert edges["pkg.d"] == set() and edges["pkg.e"] == {"pkg.d"}
    (pkg / "a.py").write_text("from .d import y\n")  # a cycle through an annotation-only import
    all_edges, _ = _imports(mods, annotations=True)
    assert _cycles(_imports(mods)[0]) == [] and _cycles(all_edges) == [["pkg.a", "pkg.d"]]


def _unannotated(tree: ast.Module) -> list[str]:
    """Public functions and methods (of public classes) with an unannotated parameter or return."""
    out = []

    def visit(node, owner=""):
        for n in ast.iter_child_nodes(node):
            if isinstance(n, ast.ClassDef) and not n.name.startswith("_"):
                visit(n, f"{n.name}.")
            elif isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and (n.name == "__init__" or not n.name.startswith("_")):
                params = [a for a in n.args.posonlyargs + n.args.args + n.args.kwonlyargs if a.arg not in ("self", "cls")]
                params += [a for a in (n.args.vararg, n.args.kwarg) if a is not None]
                if any(a.annotation is None for a in params) or (n.returns is None and n.name != "__init__"):
                    out.append(f"{owner}{n.name}")

    visit(tree)
    return out


def test_every_public_function_is_annotated():
    missing = {name: _unannotated(ast.parse(path.read_text())) for name, path in _modules().items()}
    assert {name: funcs for name, funcs in missing.items() if funcs} == {}
    assert _unannotated(ast.parse("def f(x): pass\nclass C:\n    def g(self, y: int): pass")) == ["f", "C.g"]


def _env_id_literals(tree: ast.Module) -> list[str]:
    """String constants that are a lawn environment id (``lawn/...-vN``), docstrings aside."""
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and n.body
                  and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    return [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
            and id(n) not in docstrings and n.value.startswith("lawn/") and n.value[-3:-1] == "-v"]


def test_the_multi_agent_id_is_named_in_one_place():
    import lawn_env

    where = {name: _env_id_literals(ast.parse(path.read_text())) for name, path in _modules().items()}
    assert [name for name, ids in where.items() if lawn_env.PARALLEL_ENV_ID in ids] == ["lawn_env"]
    assert lawn_env.central_env_id(lawn_env.PARALLEL_ENV_ID) == "lawn/Joint-v1"
    assert lawn_env.central_env_id("lawn/Comm-v1") == "lawn/Comm-v1"
    assert _env_id_literals(ast.parse('"""lawn/Parallel-v0 in a docstring"""\nx = "lawn/Parallel-v0"')) == [
        "lawn/Parallel-v0"]


def test_the_experts_share_their_problem_from_a_module_of_their_own():
    assert "agents.problem" in EDGES["agents.ao"] and "agents.problem" in EDGES["agents.reduced"]
    assert "agents.ao" not in EDGES["agents.reduced"]


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def _private_reads(tree: ast.Module) -> list[str]:
    """``obj._name`` reads where ``obj`` is not ``self``/``cls`` and no ``_name`` is defined in the
    module itself (as an attribute, function, class or global): a private attribute of another
    module's class."""
    own = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            own.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            own.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            own.add(node.id)
        elif isinstance(node, ast.arg):
            own.add(node.arg)
    modules = {alias.asname or alias.name for node in ast.walk(tree) if isinstance(node, ast.Import)
               for alias in node.names}  # a module's documented underscore names (os._exit) are not a class's
    modules |= {alias.asname or alias.name for node in ast.walk(tree)
                if isinstance(node, ast.ImportFrom) and node.module and node.level == 0
                for alias in node.names if _is_module(f"{node.module}.{alias.name}")}  # from numba.core import caching
    return sorted({f"{node.value.id}.{node.attr}" for node in ast.walk(tree)
                   if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                   and node.value.id not in ("self", "cls", *modules) and node.attr.startswith("_")
                   and not node.attr.startswith("__") and node.attr not in own})


def test_one_simulation_core_no_batch_twins_no_private_reads():
    lawn_modules = {name: path for name, path in _modules().items() if name.startswith("lawn_env")}
    classes = [f"{name}.{node.name}" for name, path in lawn_modules.items()
               for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.ClassDef)
               and "Simulation" in node.name]
    assert classes == ["lawn_env.core.Simulation"]
    twins = [f"{name}.{node.name}" for name, path in _modules().items()
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.endswith("_batch")]
    assert twins == []
    reads = {name: _private_reads(ast.parse(path.read_text())) for name, path in _modules().items()}
    assert {name: r for name, r in reads.items() if r} == {}
    assert _private_reads(ast.parse("def f(o):\n    return o._hidden, self._own\nclass C:\n    _x = 1\nC._x")) == [
        "o._hidden"]


def _long_functions(tree: ast.Module, limit: int) -> list[str]:
    return [f"{n.name} ({n.end_lineno - n.lineno + 1} lines)" for n in ast.walk(tree)
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > limit]


def test_the_products_keep_small_modules_and_functions():
    """No module of the learning, evaluation, paper and CLI packages over 400 lines, no function of them
    over 60."""
    training = {name: path for name, path in _modules().items() if name.split(".")[0] in PRODUCTS}
    assert {name: n for name, path in training.items() if (n := len(path.read_text().splitlines())) > 400} == {}
    long = {name: _long_functions(ast.parse(path.read_text()), 60) for name, path in training.items()}
    assert {name: fs for name, fs in long.items() if fs} == {}
    assert _long_functions(ast.parse("def f():\n" + "    x = 1\n" * 61), 60) == ["f (62 lines)"]


_COMPILERS = {"njit", "jit", "vectorize", "guvectorize", "cfunc"}


def _decorator_name(d: ast.expr) -> str:
    target = d.func if isinstance(d, ast.Call) else d
    return target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")


def _wide_functions(tree: ast.Module, limit: int, kernel_limit: int = 12) -> list[str]:
    """Functions with more than ``limit`` parameters (self/cls aside), compiled kernels
    (``@numba.njit``, ..., or a module-level alias of one, ``_kernel = numba.njit(...)``) with more
    than ``kernel_limit``."""
    compilers = _COMPILERS | {t.id for n in tree.body if isinstance(n, ast.Assign) and isinstance(n.value, ast.Call)
                              and _decorator_name(n.value) in _COMPILERS for t in n.targets if isinstance(t, ast.Name)}
    out = []
    for n in ast.walk(tree):
        if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
            compiled = any(_decorator_name(d) in compilers for d in n.decorator_list)
            params = [a for a in n.args.posonlyargs + n.args.args + n.args.kwonlyargs if a.arg not in ("self", "cls")]
            count = len(params) + (n.args.vararg is not None) + (n.args.kwarg is not None)
            if count > (kernel_limit if compiled else limit):
                out.append(f"{n.name} ({count} parameters)")
    return out


def test_the_core_and_the_agents_keep_short_and_narrow_functions():
    """No function of ``lawn_env/`` or ``agents/`` over 60 lines, compiled kernels included; no
    parameter list of any package over 8, or 12 for a compiled kernel (its arguments are its data,
    passed as a few named records)."""
    core = {name: path for name, path in _modules().items() if name.split(".")[0] in ("lawn_env", "agents")}
    long = {name: _long_functions(ast.parse(path.read_text()), 60) for name, path in core.items()}
    assert {name: fs for name, fs in long.items() if fs} == {}
    wide = {name: _wide_functions(ast.parse(path.read_text()), 8) for name, path in _modules().items()}
    assert {name: fs for name, fs in wide.items() if fs} == {}
    kernel = ("import numba\n_kernel = numba.njit(cache=True)\n@numba.njit(cache=True)\n"
              "def k(a, b, c, d, e, f, g, h, i):\n    pass\n@_kernel\ndef j(a, b, c, d, e, f, g, h, i, j, k, l, m):\n    pass\n")
    assert _wide_functions(ast.parse(kernel + "def w(a, b, c, d, e, f, g, h, *i):\n    pass\n"), 8) == [
        "j (13 parameters)", "w (9 parameters)"]


_ISSUE_NUMBER = re.compile(r"(?<![\w&])#\d{1,4}\b|\b[Ii]ssues? #?\d+")


def test_no_issue_numbers_in_code():
    """Code says why, not which ticket: no ``#NN`` or ``issue NN`` in the packages, benchmarks, scripts
    or tests (the commit messages and the issue tracker hold that history)."""
    files = [p for d in (*PACKAGES, "benchmarks", "scripts", "tests", "examples")
             for p in sorted((ROOT / d).rglob("*")) if p.suffix in (".py", ".sh") and ".venv" not in p.parts]
    found = [f"{p.relative_to(ROOT)}:{i}: {line.strip()}" for p in files
             for i, line in enumerate(p.read_text().splitlines(), 1) if _ISSUE_NUMBER.search(line)]
    assert found == []
    hash_, issue = "#", "issue"  # split, so this file's own examples are not findings
    assert _ISSUE_NUMBER.search(f"see {hash_}42") and _ISSUE_NUMBER.search(f"({issue} 12)")
    assert not _ISSUE_NUMBER.search(f"colour {hash_}1f77b4, {hash_}!/usr/bin/env, a{hash_}3")


def _local_imports(path: Path) -> int:
    """The imports of the project's own modules inside the functions of one module, each counted once."""

    def own(node: ast.AST) -> bool:
        if isinstance(node, ast.ImportFrom):
            return bool(node.level or (node.module or "").split(".")[0] in PACKAGES)
        return isinstance(node, ast.Import) and any(a.name.split(".")[0] in PACKAGES for a in node.names)

    def count(node: ast.AST, inside: bool) -> int:
        here = int(inside and own(node))
        nested = inside or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        return here + sum(count(child, nested) for child in ast.iter_child_nodes(node))

    return count(ast.parse(path.read_text()), False)


def _longest_chain(edges: dict[str, set[str]]) -> tuple[str, ...]:
    """The longest chain of imports in ``edges`` (module -> the modules it imports; acyclic)."""
    longest: dict[str, tuple[str, ...]] = {}

    def chain(m: str) -> tuple[str, ...]:
        if m not in longest:
            longest[m] = max(((m, *chain(d)) for d in edges[m]), key=len, default=(m,))
        return longest[m]

    return max((chain(m) for m in edges), key=len, default=())


def test_the_products_import_at_the_top():
    """The learning, evaluation, paper and CLI packages import the project's modules at module level: at
    most 20 imports inside functions in all (the CLI's lazy dispatch, optional extras)."""
    mods = _modules()
    local = {m: _local_imports(f) for m, f in mods.items() if m.split(".")[0] in PRODUCTS}
    assert sum(local.values()) <= 20, sorted((n, m) for m, n in local.items() if n)


#: The longest chain of module-level imports within a package: six modules, the simulator's eight. Its
#: deepest chains are stacks in which each module needs the next one when it runs: under the
#: package and an env (``envs.comm``), the engine (``envs.base``) builds the RL interface's action
#: codec, whose anchor builds the delivery law (``tail``), which builds MPCs (``mpc``) over the prediction
#: model (``dynamics``) and the compiled matrix products (``products``); and it builds the simulation
#: (``core``) over the slot kernel (``slot``), the state (``state``), the dynamics and the products.
CHAIN_LIMITS = {"lawn_env": 8}


@pytest.mark.parametrize("package", PACKAGES)
def test_each_package_keeps_its_import_chains_short(package):
    """No chain of module-level imports within one package (the imports a module runs when it is
    imported: neither those under ``if TYPE_CHECKING:`` nor those inside functions) longer than its
    limit (:data:`CHAIN_LIMITS`; six modules by default). docs/layout.md reports the simulator's."""
    edges = {m: {d for d in ds if d.split(".")[0] == package} for m, ds in MODULE_EDGES.items()
             if m.split(".")[0] == package}
    deepest = _longest_chain(edges)
    assert len(deepest) <= CHAIN_LIMITS.get(package, 6), " -> ".join(deepest)
    assert _longest_chain({"a": {"b"}, "b": {"c"}, "c": set(), "d": {"c"}}) == ("a", "b", "c")


def test_the_chain_measure_counts_module_level_imports_only(tmp_path):
    """The chains' edges: a module's top-level imports, not those in its functions or for annotations."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\nclass A:\n    from . import c\n")  # a class body runs on import
    (pkg / "b.py").write_text("def f():\n    from . import c\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import a\n")
    mods = {f"pkg.{f.stem}": f for f in sorted(pkg.glob("*.py")) if f.stem != "__init__"}
    edges, _ = _imports(mods, module_level=True)
    assert edges == {"pkg.a": {"pkg.b", "pkg.c"}, "pkg.b": set(), "pkg.c": set()}


def test_the_training_pipeline_imports_without_the_rl_extra():
    """The run spec, the recipes, the zoo's tables, the protocols and the CLI's training command import
    neither torch nor SB3: ``lawn train`` and ``lawn zoo`` load them when a run starts."""
    import subprocess
    import sys

    code = ("import sys, training.spec, training.train, training.recipes, training.zoo, evaluation.protocols, "
            "lawn_cli.train, lawn_cli.zoo; print('torch' in sys.modules, 'stable_baselines3' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["False", "False"]
