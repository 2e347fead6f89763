"""The short robustness matrix in CI: simulated drives replayed with config/default.yaml alone.

A 30 Hz and a 200 Hz IMU with 2 ms stamp jitter (bench/bench_robustness.py, the full matrix is
the bench): each must align within 30 s of the start of motion (the drive stands still for its
first 30 s), reach a horizontal RMS after alignment of at most half the raw fixes', and publish
no fix flagged valid before alignment or beyond 5 sigma of its own covariance.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("cell", [0, 3])
def test_default_profile_navigates_a_simulated_drive(cell):
    run = subprocess.run([sys.executable, str(REPO / "bench" / "bench_robustness.py"), "--json",
                          "--duration", "60", "--cells", str(cell)],
                         capture_output=True, text=True, cwd=REPO, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    assert result["align_s"] <= 30.0 + 30.0, result
    assert result["ratio"] <= 0.5, result
    assert result["valid_early"] == 0 and result["valid_beyond_5_sigma"] == 0, result
    assert result["valid_fixes"] > 100, result
