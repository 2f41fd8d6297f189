import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("NUMBA_NUM_THREADS", "2")
# torch ops in these tiny tests run fastest single-threaded; with pytest-xdist workers and other
# jobs sharing the cores, torch's default thread pool oversubscribes them (10x slower measured).
os.environ.setdefault("OMP_NUM_THREADS", "1")
