"""The app's window loads numba's counting kernel in its own thread before any worker starts (core.preload):
in the workers, loading it took the interpreter lock for tens of ms and stalled a first file open of the
process (mono 1000²: 70-83 ms; 24-28 ms with the warm-up; benchmarks/results/ui_stalls_xeon.md). Checked in a
fresh interpreter: after preload, counting a real file (mono and Bayer) needs no new kernel signature."""

from __future__ import annotations

import json
import subprocess
import sys

_CHILD = r"""
import json, sys
import numpy as np
from spikeview.session import core
from spikeview.io import _packed, open_source, write_plain

core.preload()
before = [str(s) for s in _packed._count_kernel.signatures]
rng = np.random.default_rng(0)
for i, cfa in enumerate(("none", "RGGB")):
    path = f"{sys.argv[1]}/c{i}.dat"
    write_plain(path, (rng.random((30, 8, 16)) < 0.3).astype(np.uint8))
    with open_source(path, width=16, height=8, cfa=None if cfa == "none" else cfa) as src:
        src.count(0, 10)
print(json.dumps({"before": before, "after": [str(s) for s in _packed._count_kernel.signatures]}))
"""


def test_preload_loads_the_counting_kernel_that_a_file_open_uses(tmp_path):
    r = subprocess.run([sys.executable, "-c", _CHILD, str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    assert len(res["before"]) == 1, res  # loaded by preload, in the calling thread
    assert res["after"] == res["before"], res  # a file's counts use that very signature: nothing left to load
