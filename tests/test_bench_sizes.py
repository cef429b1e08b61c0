"""The size benchmark's peak memory is the command's own, not the benchmark process's it was started from."""

import subprocess
import sys

import numpy as np

from experiments.bench_sizes import _LAUNCH


def test_the_launcher_reports_the_commands_own_peak(tmp_path):
    held = np.ones(400 << 20, np.uint8)  # the benchmark's own 400 MiB (images, say)
    peak = tmp_path / "peak"
    child = "x = bytearray(100 << 20); x[::4096] = b'1' * len(x[::4096])"  # 100 MiB touched
    run = subprocess.run([sys.executable, "-c", _LAUNCH, str(peak), sys.executable, "-c", child])
    assert run.returncode == 0 and held[-1] == 1
    mib = int(peak.read_text()) / 1024
    assert 100 <= mib < 250, mib  # the child's 100 MiB and an interpreter, not 400 more
