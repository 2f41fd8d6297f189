"""TFI at 1000x1000, half window 32: the current kernel against the one before the stream-ends rule (commit 1c248e2),
interleaved in one run, medians after a warm-up, mid-stream and at the stream's ends.

    git show 1c248e2:spikeview/classical/tfi.py > /tmp/tfi_old.py && python benchmarks/bench_tfi_ends.py /tmp/tfi_old.py
"""
import importlib.util
import sys
import time

import numpy as np

spec = importlib.util.spec_from_file_location("tfi_old", sys.argv[1])
O = importlib.util.module_from_spec(spec)
sys.modules["tfi_old"] = O
spec.loader.exec_module(O)
from spikeview.classical import tfi as N
rng = np.random.default_rng(0)
sp = (rng.random((65, 1000, 1000)) < 0.1).astype(np.uint8)
for f in (O.tfi_array, N.tfi_array): f(sp, 32, 32)
t = {"old": [], "new": []}
for _ in range(9):
    for name, f in (("old", O.tfi_array), ("new", N.tfi_array)):
        t0 = time.perf_counter(); f(sp, 32, 32); t[name].append(time.perf_counter() - t0)
m = {k: float(np.median(v)) * 1000 for k, v in t.items()}
print(f"mid-stream 1000x1000 hw 32: previous {m['old']:.1f} ms, now {m['new']:.1f} ms, ratio {m['new']/m['old']:.2f}")
np.testing.assert_array_equal(O.tfi_array(sp, 32, 32), N.tfi_array(sp, 32, 32))
print("mid-stream output identical")
for t_ in (0, 64):
    tt = {"old": [], "new": []}
    for _ in range(7):
        for name, f in (("old", O.tfi_array), ("new", N.tfi_array)):
            t0 = time.perf_counter(); f(sp, t_, 32); tt[name].append(time.perf_counter() - t0)
    mm = {k: float(np.median(v)) * 1000 for k, v in tt.items()}
    print(f"tick {t_} (the stream's end): previous {mm['old']:.1f} ms, now {mm['new']:.1f} ms (the ends' rule)")
