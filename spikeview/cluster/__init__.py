"""Long captures in chunks: reconstruct a range of windows into one Zarr store, in-process or on Dask.

The batch path behind ``spikeview reconstruct INPUT --range A:B:STEP --out OUT.zarr``:

* :mod:`spikeview.cluster._compute` — the **one** adapter to the reconstruction library: the
  sequence-wide state (colour cast α, white point) computed once, and ``compute_chunk`` (frames of
  a run of windows). Workers open the source and load the prior once per process (a cached
  loader), reading the input from its shared file path.
* :mod:`spikeview.cluster.store` — the Zarr layout: ``frames`` (N, H, W, C) float32 linear (the white
  point is an attribute; ``spikeview export`` maps by it) in chunks of W windows, the window ticks, the
  recipe as attributes, per-chunk completion markers; :func:`~spikeview.cluster.store.check_store`
  validates a store before it is read.
* :mod:`spikeview.cluster.run` — the driver: in-process loop or Dask client (``local:N`` or
  ``tcp://HOST:PORT``), resume, retries, progress (window by window; workers send events).
* :mod:`spikeview.cluster.reconstruct` — :func:`reconstruct_to_store`, the one call for front ends
  (the CLI's ``--out OUT.zarr``; the app's export panel can call it from a background job).

Chunking changes nothing: α is resolved before the split, the sampler seeds per window, and the
guided sampler's reuse / warm start restart at fixed *keyframes* (every ``keyframe`` windows, the
same for every chunk size); a chunk that starts between keyframes recomputes its lead-in from the
previous keyframe and discards it. So frames do not depend on the chunk size or the workers.

Nothing here is imported by ``spikeview --help`` or ``import spikeview``: dask and zarr are the
optional ``spikeview[cluster]`` extra.
"""

from __future__ import annotations
