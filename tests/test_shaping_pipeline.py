"""The layout of `design_move`'s pipeline: validate → build the candidates → measure → the minimax rows → rank, each
stage a module that imports only the modules below it, and `design_move` a short composition of them."""

import ast
from pathlib import Path

SHAPING = Path(__file__).resolve().parents[1] / "jaxbelt" / "shaping"

#: the pipeline's modules from the bottom up: each may import only the ones before it (among these)
ORDER = (
    "bands",
    "shaped",
    "hull",
    "far_modes",
    "request",
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
