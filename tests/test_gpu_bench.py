"""`benchmarks/gpu.py` runs on any backend (here the CPU) and measures what it says: a batch that agrees with
`simulate`, its bytes, XLA's account of its memory, and a χ sweep that agrees with a tight solve."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_gpu_benchmark_script_runs_on_the_cpu_and_checks_its_numbers(tmp_path):
    env = dict(os.environ, JAXBELT_BENCH_OUT=str(tmp_path), MPLBACKEND="Agg")
    run = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "gpu.py"), "--quick", "--repeats", "2"],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads((tmp_path / "gpu.json").read_text())
    assert (tmp_path / "gpu.png").stat().st_size > 0
    cpu = result["sections"]["cpu"]
    (batch,) = cpu["batches"]
    assert "error" not in batch, batch
    assert batch["output_bytes"] == 1000 * 501 * 5 * 8  # B x times x states, float64
    assert batch["rel_error"] < 1e-10  # three elements against simulate's closed form
    assert batch["xla_output_bytes"] == batch["output_bytes"]
    assert 1.0 <= (batch["xla_output_bytes"] + batch["xla_temp_bytes"]) / batch["output_bytes"] < 3.0
    assert batch["write_rate"] > 0 and batch["copy_rate"] > 0
    (sweep,) = cpu["sweeps"]
    assert sweep["chi_abs_error"] < 1e-5  # Tsit5 at rtol 1e-6 against rtol 1e-10
    whats = {t["what"] for t in result["targets"]}
    assert whats == {"peak memory / output, batch 1000", "write rate / copy rate, batch 1000"}
