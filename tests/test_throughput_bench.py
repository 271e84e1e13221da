"""The throughput benchmark's correctness path: its batched sweeps equal independent references.

Tiny batches (4 elements) only; the timing itself lives in `benchmarks/throughput.py`.
"""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parent.parent / "benchmarks"


@pytest.fixture(scope="module")
def tp():
    sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location("throughput_bench", BENCH / "throughput.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("scene", ["startup", "shaping", "runout"])
def test_batch_equals_scalar_loop(tp, scene):
    # reference: a Python loop of scalar calls (startup: the matrix-exponential solve, not the batched
    # closed form); tolerance 1e-9 relative to each column's peak (both are closed forms in float64)
    x = tp.random_inputs(scene, 4, seed=3)
    out, ref = tp.batch_and_reference(scene, x)
    assert out.shape == ref.shape
    assert tp.max_rel_diff(out, ref) < 1e-9


def test_span_frequencies_match_eq39(tp):
    # reference: eq. (39) of the belt-vibration report written out in numpy, checked here at V = 0 by hand too
    x = tp.random_inputs("span_freqs", 4, seed=3)
    out, ref = tp.batch_and_reference("span_freqs", x)
    np.testing.assert_allclose(out, ref, rtol=1e-12)
    vc = np.sqrt(140.0 / 0.05)
    np.testing.assert_allclose(
        tp.span_freqs_closed_form(np.array([0.0]))[0], np.pi / 0.2621 * vc * np.arange(1, 4), rtol=1e-14
    )


def test_max_rel_diff_is_per_column(tp):
    ref = np.array([[1.0, 1000.0], [2.0, 2000.0]])
    x = ref + np.array([[0.0, 0.0], [0.02, 0.0]])
    assert tp.max_rel_diff(x, ref) == pytest.approx(0.01)
