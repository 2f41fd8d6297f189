"""Error against run time of TFP, TFI, the strong baseline and the guided sampler.

The implementation ships in the package (``spikeview bench`` runs the same code); see
:mod:`spikeview.bench.guided`. Usage: ``python benchmarks/bench_guided.py [--quick] [--out DIR]``.
"""

from spikeview.bench.guided import main

if __name__ == "__main__":
    raise SystemExit(main())
