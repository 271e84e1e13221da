"""The layout of `design_move`'s pipeline: validate → build the candidates → measure → the minimax rows → rank, each
stage a module that imports only the modules below it, and `design_move` a short composition of them."""

import ast
from pathlib import Path

import pytest

SHAPING = Path(__file__).resolve().parents[1] / "jaxbelt" / "shaping"

#: the pipeline's modules from the bottom up: each may import only the ones before it (among these)
ORDER = (
    "bands",
    "hull",
    "far_modes",
    "request",
    "shaped",
    "certificate",
    "minimax_solve",
    "candidates",
    "measure",
    "minimax_rows",
    "rank",
    "plan",
)


def _imported(name: str, folder: Path = SHAPING) -> set[str]:
    """The modules of `ORDER` that `folder`/`name`.py imports (relative imports, at any depth of the file)."""
    tree = ast.parse((folder / f"{name}.py").read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module is None:
                out |= {a.name for a in node.names}
            else:
                out.add(node.module.split(".")[0])
    return out & set(ORDER)


def test_each_stage_imports_only_the_modules_below_it():
    for i, name in enumerate(ORDER):
        above = _imported(name) - set(ORDER[:i])
        assert not above, f"jaxbelt/shaping/{name}.py imports {sorted(above)}, which stand above it in {ORDER}"


def test_the_check_sees_an_import_that_runs_back_up(tmp_path):
    """The import scan finds a relative import, also one inside a function (as a lazy import would be)."""
    (tmp_path / "measure.py").write_text("import numpy\n\n\ndef f():\n    from .candidates import classic_commands\n")
    assert _imported("measure", tmp_path) == {"candidates"}


def test_design_move_only_composes_the_stages():
    """`design_move` (signature, docstring and body) stays within 60 lines, the issue's bound for a composition."""
    tree = ast.parse((SHAPING / "plan.py").read_text())
    fn = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "design_move")
    assert fn.end_lineno is not None
    assert fn.end_lineno - fn.lineno + 1 <= 60


#: the stages after `request.validate`: they take plain data from the request
_AFTER_VALIDATE = ("bands", "shaped", "hull", "certificate", "minimax_solve", "candidates", "measure", "minimax_rows")


def test_no_stage_after_validate_re_enters_the_checks_or_the_axis_constructor():
    """Validate once: no later stage imports `jaxbelt._checks` or builds a `ModalAxis(...)` (they take the request's
    checked arrays; `far_modes.modes_axis` makes an axis of them without checking them again)."""
    for name in (*_AFTER_VALIDATE, "rank", "far_modes"):
        tree = ast.parse((SHAPING / f"{name}.py").read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                assert node.module != "_checks", f"jaxbelt/shaping/{name}.py imports jaxbelt._checks"
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                assert node.func.id != "ModalAxis", (
                    f"jaxbelt/shaping/{name}.py builds a ModalAxis at line {node.lineno}"
                )


def test_modes_axis_is_the_checked_constructor_without_its_checks():
    """`far_modes.modes_axis` holds what `ModalAxis(f, z, g)` holds (float64 device arrays, no standard errors), and
    its residuals are those of the constructed axis (closed form), to the last bit."""
    import jax
    import numpy as np

    import jaxbelt as jb
    from jaxbelt.shaping.far_modes import _sub_axis, modes_axis
    from jaxbelt.shaping.moves import fastest_move
    from jaxbelt.shaping.residual import measured_curve

    axis = jb.ModalAxis([7.3, 18.0], [0.015, 0.01], [1.0, -0.5], frequency_std=[0.1, 0.2], damping_std=[1e-3, 1e-3])
    f, z, g = np.array([7.3, 7.3, 18.0]), np.array([0.01, 0.1, 0.01]), np.array([1.0, 1.0, -0.5])
    made, built = modes_axis(axis, f, z, g), jb.ModalAxis(f, z, g)
    for name in ("frequencies", "damping_ratios", "gains"):
        got, want = getattr(made, name), getattr(built, name)
        assert isinstance(got, jax.Array) and got.dtype == want.dtype == np.float64
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    assert made.frequency_std is None and made.damping_std is None
    cmd, factors = fastest_move(0.1, 0.5, 3.0), np.linspace(0.8, 1.2, 9)
    np.testing.assert_array_equal(
        np.asarray(measured_curve(made, cmd, factors)), np.asarray(measured_curve(built, cmd, factors))
    )
    sub = _sub_axis(axis, [1])
    np.testing.assert_array_equal(np.asarray(sub.frequencies), [18.0])
    np.testing.assert_array_equal(np.asarray(sub.gains), [-0.5])


def test_convolved_is_shape_move_without_its_checks():
    """`moves.convolved` (the shaped moves of `design_move`'s candidates) is `moves.shape_move`'s move exactly; the
    checks stay with `shape_move` (a sum of amplitudes other than 1 is refused by name)."""
    import numpy as np
    import pytest

    from jaxbelt.shaping.moves import _trapezoid_move, convolved, shape_move

    base = _trapezoid_move(0.1, 0.4, 0.5, 3.0, None)
    A, tau = np.array([0.6, 0.4]), np.array([0.0, 0.05])
    a, b = convolved(base, A, tau), shape_move(base, A, tau)
    for name in ("times", "steps", "ramps", "duration"):
        np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)))
    with pytest.raises(ValueError, match="amplitudes"):
        shape_move(base, np.array([0.6, 0.6]), tau)


@pytest.mark.slow  # compiles the curve programs of five command kinds (~10 s)
def test_closed_curve_is_measured_curve_for_every_candidate_kind():
    """`residual.closed_curve` (the pipeline's curve: no ODE branch, the quadrature's poles on the host) gives
    `measured_curve`'s numbers to the last bit for every kind of command the pipeline measures: a piecewise move
    (plain and shaped), a spline, a blend of both, a pseudo-polynomial (plain and shaped), on the band's 401 factors
    (padded to a slot) and on 9 (not padded); and the public `residual_curve`'s (checked, its factors unpadded) to
    1e-12 of the curve's largest value (a padded uniform grid's blocked sums round differently)."""
    import numpy as np

    import jaxbelt as jb
    from jaxbelt.commands import PseudoPolynomial, ShapedCommand
    from jaxbelt.shaping.hull import blend_moves
    from jaxbelt.shaping.moves import SplineMove, convolved, fastest_move
    from jaxbelt.shaping.residual import closed_curve, measured_curve, residual_curve

    axis = jb.ModalAxis([7.3, 18.0], [0.015, 0.01], [1.0, -0.5])
    base = fastest_move(0.1, 0.3, 1.2)
    T = float(base.duration)
    shaped = convolved(base, np.array([0.6, 0.4]), np.array([0.0, 0.05]))
    coef = np.sin(np.arange(13.0))
    spline = SplineMove(coef - coef.mean(), T)
    pseudo = PseudoPolynomial(np.array([3.0, 4.0, 5.0]), 0.1, T)
    cmds = (base, shaped, spline, blend_moves([spline, base], [0.3, 0.7]), pseudo)
    cmds += (ShapedCommand(pseudo, np.array([0.0, 0.05]), np.array([0.5, 0.5])),)
    for factors in (np.linspace(0.8, 1.2, 401), np.linspace(0.9, 1.1, 9)):
        for cmd in cmds:
            got = closed_curve(axis, cmd, factors)
            assert isinstance(got, np.ndarray) and got.shape == (2, factors.size)
            np.testing.assert_array_equal(got, np.asarray(measured_curve(axis, cmd, factors)))
            public = np.asarray(residual_curve(axis, cmd, factors))
            assert np.max(np.abs(got - public)) <= 1e-12 * np.max(public)
