"""The package's import graph has no cycle, and `import jaxbelt` has no surprising side effects."""

import ast
import os
import pathlib
import subprocess
import sys

import pytest

import jaxbelt

PKG = pathlib.Path(jaxbelt.__file__).parent


def _module_name(path: pathlib.Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: pathlib.Path, name: str) -> set:
    """Every jaxbelt module that `path` imports, at module level or inside functions."""
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("jaxbelt")}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                root = base[: len(base) - (node.level - 1)]
                mod = ".".join(root + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if not mod.startswith("jaxbelt"):
                continue
            found.add(mod)
            for a in node.names:  # `from . import x` may name a submodule
                found.add(f"{mod}.{a.name}")
    return found


def _graph():
    modules = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        deps = {d for d in _imports(path, name) if d in modules and d != name}
        # importing a.b.c runs a/__init__ and a/b/__init__ first: that is Python's doing, not an edge
        graph[name] = {d for d in deps if not name.startswith(d + ".")}
    return graph


def _cycle(graph):
    state = {}

    def visit(n, stack):
        state[n] = 1
        stack.append(n)
        for d in sorted(graph[n]):
            if state.get(d) == 1:
                return stack[stack.index(d) :] + [d]
            if d not in state:
                c = visit(d, stack)
                if c:
                    return c
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state:
            c = visit(n, [])
            if c:
                return c
    return None


def test_import_graph_has_no_cycle():
    # package __init__ files re-export their children; edges out of them are re-exports, not dependencies
    graph = {
        n: (set() if (PKG.parent / n.replace(".", "/") / "__init__.py").exists() else deps)
        for n, deps in _graph().items()
    }
    graph = {
        n: {d for d in deps if not (PKG.parent / d.replace(".", "/") / "__init__.py").exists()}
        for n, deps in graph.items()
    }
    assert len(graph) > 30
    assert _cycle(graph) is None, f"import cycle: {' -> '.join(_cycle(graph))}"


def test_cycle_detector_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def _folder_loop(graph, packages):
    """A loop through a package seen as one room: a module of `package` imports a module outside it that
    (directly or further on) imports back into `package` (e.g. models/* -> solve -> models/base), which
    the file-level test does not see because no file imports itself. `graph`: {module: imported modules};
    `packages`: the package names to look at. Returns the loop as a list of names (the package standing
    for its modules), or None."""
    for package in sorted(packages):

        def room(n, package=package):
            return package if n == package or n.startswith(package + ".") else n

        folded = {}
        for n, deps in graph.items():
            folded.setdefault(room(n), set()).update(room(d) for d in deps if room(d) != room(n))
        for n in set().union(*folded.values()) - set(folded):
            folded[n] = set()
        loop = _cycle(folded)
        if loop is not None:
            return loop
    return None


def _folder_graph():
    """The module graph for the folder-level test: a package's `__init__` that hands on its own children's
    names (re-exports, imported on first use) does not depend on them."""
    packages = {n for n in _graph() if (PKG.parent / n.replace(".", "/") / "__init__.py").exists()}
    graph = {n: {d for d in deps if not (n in packages and d.startswith(n + "."))} for n, deps in _graph().items()}
    return graph, packages


def test_no_folder_imports_itself_through_another_module():
    graph, packages = _folder_graph()
    assert {"jaxbelt.models", "jaxbelt.models.nonlinear", "jaxbelt.cli", "jaxbelt.plots"} <= packages
    loop = _folder_loop(graph, packages - {"jaxbelt"})
    assert loop is None, f"folder-level import loop: {' -> '.join(loop)}"


def test_folder_loop_detector_finds_a_loop_through_a_package():
    # models/startup -> solve -> models/base: no file-level cycle, a loop through the folder `models`
    graph = {"models": set(), "models.startup": {"solve"}, "models.base": set(), "solve": {"models.base"}}
    assert _cycle(graph) is None
    assert _folder_loop(graph, {"models"}) == ["models", "solve", "models"]
    # the same arrow from solve into a module of its own floor: no loop
    graph["solve"] = {"protocol"}
    graph["protocol"] = set()
    assert _folder_loop(graph, {"models"}) is None
    # a loop through a nested package is the loop of the package that holds it too
    graph = {"m.n.a": {"x"}, "x": {"m.n.b"}, "m.n.b": set()}
    assert _folder_loop(graph, {"m"}) == ["m", "x", "m"]
    assert _folder_loop(graph, {"m.n"}) == ["m.n", "x", "m.n"]


def test_import_loads_no_plotting_library_and_changes_no_configuration():
    code = "import sys, jax; import jaxbelt as jb; print('matplotlib' in sys.modules, jax.config.jax_enable_x64)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False"]


_HEAVY = ("diffrax", "optax", "optimistix", "lineax", "matplotlib", "matplotlib.pyplot")


def _loaded_after(*steps: str) -> list[set]:
    """The heavy libraries loaded after each of `steps`, run one after the other in one fresh process (each set
    holds what the steps up to it loaded: a library a step loads is absent from the set before it)."""
    probe = "import sys\n" + "".join(
        f"{code}\nprint(' '.join(m for m in {_HEAVY!r} if m in sys.modules) + ' |')\n" for code in steps
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    sets = [set(chunk.split()) for chunk in out.stdout.split("|")[:-1]]
    assert len(sets) == len(steps), out.stdout
    return sets


def test_import_and_the_startup_closed_form_load_only_what_they_use():
    # `import jaxbelt` imports no heavy library; the start-up closed form adds equinox, never an ODE solver,
    # an optimiser or a plotting library; the first name of an optimiser loads its optimisation library, the
    # first ODE solve diffrax (two processes, each step's libraries read after it: what a step loads is what was
    # absent before it)
    imported, closed_form, ode, optimiser = _loaded_after(
        "import jaxbelt",
        "import jax, jaxbelt as jb, numpy as np; jax.config.update('jax_enable_x64', True); "
        "ts, c = jb.startup_curves(gammas=[0.02], n_points=11); "
        "assert np.all(np.isfinite(c['current']))",
        "jb.simulate(jb.Scene(jb.FourBarDrive(), jb.PID(), ts=jax.numpy.linspace(0.0, 0.01, 3)))",
        "jb.tune_pid",
    )
    assert imported == set() and closed_form == set()
    assert "diffrax" in ode and "optax" not in ode  # optax absent before the optimiser's name: its step loads it
    assert "optax" in optimiser
    # the residual energy by its default quadrature, and an optimisation of it, need no ODE solver (0.26 s of
    # their first call); its `method="ode"` loads diffrax when called
    shaping = (
        "import jax, jaxbelt as jb; jax.config.update('jax_enable_x64', True); "
        "plat, cmd = jb.BeltPlatform(), jb.PseudoPolynomial(jax.numpy.array([3.0, 4.0, 5.0])); "
    )
    quadrature, ode = _loaded_after(
        shaping + "jb.optimise_command(plat, cmd, progress=False)", "jb.residual_energy(plat, cmd, method='ode')"
    )
    assert "diffrax" not in quadrature
    assert "diffrax" in ode


def _lazy_packages():
    from jaxbelt import _lazy

    return [
        (name, _lazy.exports(PKG.parent / name.replace(".", "/") / "__init__.py"))
        for name in ("jaxbelt", "jaxbelt.models", "jaxbelt.plots")
    ]


def test_every_lazy_name_is_the_object_its_module_defines():
    import importlib

    for package, table in _lazy_packages():
        pkg = importlib.import_module(package)
        assert set(table) <= set(dir(pkg)) and set(table) <= set(pkg.__all__)
        for name, (module, attr) in table.items():
            target = importlib.import_module(f"{package}.{module}")
            assert getattr(pkg, name) is (target if attr is None else getattr(target, attr)), f"{package}.{name}"
            # a name that is also a sub-module's name would be overwritten by that sub-module's import
            if attr is not None:
                assert not (PKG.parent / package.replace(".", "/") / f"{name}.py").exists(), f"{package}.{name}"
                assert not (PKG.parent / package.replace(".", "/") / name).is_dir(), f"{package}.{name}"
        with pytest.raises(AttributeError, match=f"module '{package}' has no attribute 'no_such_name'"):
            _ = pkg.no_such_name
    # sub-modules are reached as attributes, as an eager import made them
    assert jaxbelt.models.fourbar.FourBarDrive is jaxbelt.FourBarDrive


def test_lazy_table_refuses_other_statements(tmp_path):
    from jaxbelt import _lazy

    init = tmp_path / "__init__.py"
    init.write_text("import typing\nif typing.TYPE_CHECKING:\n    import numpy\n")
    with pytest.raises(ImportError, match="TYPE_CHECKING block may hold only"):
        _lazy.exports(init)
    init.write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import b as b\n    from . import c as c\n"
    )
    assert _lazy.exports(init) == {"b": ("a", "b"), "c": ("c", None)}


def test_first_use_inside_a_callers_jit_gives_the_eager_values():
    # `import jaxbelt` loads a module on the first use of one of its names, which may happen inside a caller's
    # jit: the modules' own state (e.g. which trace counts as eager) must not depend on that. Fresh process,
    # first uses inside jit: an ODE start-up (jaxbelt's core and diffrax), then the residual energy (checks
    # that run as host callbacks inside a trace); the same values eagerly afterwards, to 1e-12.
    code = """
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import jaxbelt as jb
ts = jnp.linspace(0.0, 0.1, 11)
ode = jax.jit(lambda v: jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(v, 0.02), ts=ts), method="ode",
                                    rtol=1e-10, atol=1e-12).ys)
energy = jax.jit(lambda g: jb.residual_energy(jb.BeltPlatform(), jb.PseudoPolynomial(g)))
y_jit, h_jit = ode(24.0), energy(jnp.array([3.0, 4.0, 5.0]))
y = jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.02), ts=ts), method="ode", rtol=1e-10, atol=1e-12).ys
h = jb.residual_energy(jb.BeltPlatform(), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])))
np.testing.assert_allclose(y_jit, y, rtol=1e-12, atol=1e-12)
np.testing.assert_allclose(h_jit, h, rtol=1e-12)
assert float(h) > 0 and np.all(np.isfinite(y))
print("ok")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.split() == ["ok"], out.stderr[-3000:]


def test_lazy_module_imported_inside_a_trace_keeps_concrete_arrays(tmp_path):
    # a library a traced program needs is imported at its first attribute read, often while jaxbelt traces a
    # program: its import-time arrays are values, not tracers of that program (a leaked tracer fails later)
    (tmp_path / "lib_with_arrays.py").write_text("import jax.numpy as jnp\nTABLE = jnp.arange(3.0) * 2.0\n")
    code = (
        "import jax, jax.numpy as jnp, numpy as np\n"
        "from jaxbelt._lazy import lazy_module\n"
        "lib = lazy_module('lib_with_arrays')\n"
        "out = jax.jit(lambda x: x + lib.TABLE)(1.0)\n"
        "import lib_with_arrays\n"
        "assert not isinstance(lib_with_arrays.TABLE, jax.core.Tracer)\n"
        "np.testing.assert_array_equal(np.asarray(out), [1.0, 3.0, 5.0])\n"
        "np.testing.assert_array_equal(np.asarray(lib.TABLE), [0.0, 2.0, 4.0])\n"
    )
    env = dict(os.environ, PYTHONPATH=f"{tmp_path}{os.pathsep}{PKG.parent}")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
