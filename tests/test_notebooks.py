"""Every notebook in notebooks/ is executed top to bottom; a cell that raises fails the test.

The cells run in an IPython shell inside the test process (the machinery of a Jupyter kernel,
without the kernel process): a fresh namespace per notebook, the notebook's folder a temporary
one, and after each cell every open figure is rendered to PNG and closed, as the inline backend
of a kernel does. In the test process a notebook reuses the programs its scene's tests compiled
(conftest.py hands both to the same xdist worker); a kernel would compile them all again.
"""

import builtins
import contextlib
import io
import os
import sys
import warnings
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))


@contextlib.contextmanager
def _ipython_shell(workdir):
    """A fresh IPython shell; the process state it touches (builtins, `__main__`, cwd) is restored."""
    from IPython.core.interactiveshell import InteractiveShell
    from traitlets.config import Config

    cfg = Config()
    cfg.HistoryManager.enabled = False  # no history database
    cfg.InteractiveShell.colors = "NoColor"  # plain tracebacks in the test report
    saved_builtins = dict(builtins.__dict__)
    saved_main, saved_cwd = sys.modules["__main__"], os.getcwd()
    shell = InteractiveShell.instance(config=cfg)
    try:
        os.chdir(workdir)
        yield shell
    finally:
        os.chdir(saved_cwd)
        shell.restore_sys_module_state()
        sys.modules["__main__"] = saved_main
        for name in set(builtins.__dict__) - set(saved_builtins):
            del builtins.__dict__[name]
        builtins.__dict__.update(saved_builtins)
        import atexit

        atexit.unregister(shell.atexit_operations)
        InteractiveShell.clear_instance()


def _render_open_figures():
    """Draw every open figure to PNG (as a kernel's inline backend does at the end of a cell) and close it."""
    import matplotlib.pyplot as plt

    for num in plt.get_fignums():
        plt.figure(num).savefig(io.BytesIO(), format="png", bbox_inches="tight")
    plt.close("all")


@pytest.mark.notebook
@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path):
    nbformat = pytest.importorskip("nbformat")
    pytest.importorskip("IPython")
    import matplotlib.pyplot as plt

    plt.close("all")
    with warnings.catch_warnings():
        # a cell without an id: a warning of nbformat today, an error in its later versions
        warnings.simplefilter("error", nbformat.validator.MissingIDFieldWarning)
        nb = nbformat.read(path, as_version=4)
    cells = [cell for cell in nb.cells if cell.cell_type == "code"]
    assert cells
    with _ipython_shell(tmp_path) as shell:
        for k, cell in enumerate(cells):
            with warnings.catch_warnings():
                # plt.show() on the test process's Agg backend; the figures are rendered below
                warnings.filterwarnings("ignore", message=".*non-interactive, and thus cannot be shown")
                result = shell.run_cell(cell.source, store_history=False)
            if not result.success:
                pytest.fail(
                    f"{path.name}: code cell {k + 1} raised:\n{cell.source}\n\n{result.error_in_exec or result.error_before_exec!r}"
                )
            _render_open_figures()


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_turns_64_bit_mode_on_in_its_first_cell(path):
    """jaxbelt changes no configuration on import: each notebook turns JAX's 64-bit mode on itself, in its
    first code cell, right after the imports (before anything can make an array)."""
    import json

    first = next(c for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code")
    source = "".join(first["source"])
    line = 'jax.config.update("jax_enable_x64", True)'
    assert line in source, f"{path.name}: the first code cell does not turn 64-bit mode on"
    above = source[: source.index(line)].splitlines()
    assert all(ln.startswith(("import ", "from ")) or not ln.strip() for ln in above), above
