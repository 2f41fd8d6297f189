"""Views of a source: the same spikes read another way, without copying.

* :class:`LockedSource` serialises reads (the app's preview, guided and export workers share one
  source; file readers keep a file position);
* :class:`ViewSource` re-interprets a stream — flipped vertically and/or with another CFA name —
  that cannot be re-opened from a file (the simulated demo).
"""

from __future__ import annotations

import threading

import numpy as np

from spikeview.cfa import parse_cfa
from spikeview.io.source import SpikeSource


class LockedSource(SpikeSource):
    """A :class:`SpikeSource` whose reads are serialised by a lock.

    The preview worker, the guided worker and the exporter read the same source from different
    threads; file readers keep a file position, so reads must not interleave.
    """

    def __init__(self, inner: SpikeSource):
        self.inner = inner
        self.info = inner.info
        self._lock = threading.Lock()

    def _read(self, a: int, b: int) -> np.ndarray:
        with self._lock:
            return self.inner.read(a, b)

    def count(self, a: int, b: int) -> np.ndarray:
        with self._lock:
            return self.inner.count(a, b)

    def close(self) -> None:
        with self._lock:
            self.inner.close()


class ViewSource(SpikeSource):
    """Another reading of a source: its frames flipped vertically and/or a different CFA name.

    Used to re-interpret a stream that cannot be re-opened from a file (the simulated demo). The
    CFA names the top-left 2×2 of what :meth:`read` returns, as everywhere.
    """

    def __init__(self, inner: SpikeSource, cfa: str | None, flip_vertical: bool):
        self.inner = inner
        self.flip = bool(flip_vertical)
        self.info = inner.info.replace(cfa=parse_cfa(cfa), flip_vertical=self.flip)

    def _read(self, a: int, b: int) -> np.ndarray:
        out = self.inner.read(a, b)
        return np.ascontiguousarray(out[:, ::-1]) if self.flip else out

    def count(self, a: int, b: int) -> np.ndarray:
        out = self.inner.count(a, b)
        return np.ascontiguousarray(out[::-1]) if self.flip else out

    def close(self) -> None:
        self.inner.close()
