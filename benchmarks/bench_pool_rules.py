"""The pooling (pool_counts, ±3 windows) before this session's rules (commit 1c248e2) and now, interleaved, medians of 5.

    git show 1c248e2:spikeview/guided/temporal.py > /tmp/o/temporal_old.py
    spikeview simulate --demo --size 1000 --ticks 200 --out /tmp/p/demo1000.dat
    python benchmarks/bench_pool_rules.py
"""
import numpy as np, sys, time, importlib.util
spec = importlib.util.spec_from_file_location("spikeview.guided.temporal_old", "/tmp/o/temporal_old.py")
O = importlib.util.module_from_spec(spec); sys.modules[spec.name] = O; spec.loader.exec_module(O)
from spikeview.guided import temporal as T
from spikeview.io import open_source
for name, f in (("demo 1000² RGGB", "/tmp/p/demo1000.dat"), ("uhsr.npz", "/work/main/tests/data/uhsr.npz")):
    src = open_source(f); c = src.n_frames // 2; cfa = src.cfa
    for M in (O, T): M.pool_counts(src, c - 5, c + 5, 3, cfa)
    t = {"old": [], "new": []}
    for _ in range(5):
        for k, M in (("old", O), ("new", T)):
            t0 = time.perf_counter(); M.pool_counts(src, c - 5, c + 5, 3, cfa); t[k].append(time.perf_counter() - t0)
    m = {k: float(np.median(v)) for k, v in t.items()}
    print(f"{name}: pool_counts ±3 median of 5: before {m['old']:.3f} s, now {m['new']:.3f} s, ratio {m['new']/m['old']:.2f}")
