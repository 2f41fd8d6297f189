"""The guided path's one-time start-up, begun in a background thread while the caller reads the capture.

A guided run of a fresh process first pays about 1.5 s that does not depend on the data: importing
torch, probing the CPU for the prior's precision (:func:`spikeview.guided.precision.resolve_precision`),
loading the prior's weights and checking OpenVINO (:func:`spikeview.guided.priors.ov_backend.available`).
The command line reads the capture meanwhile (its colour cast, white point and the temporal pooling
of the first window: numpy and numba work that releases the GIL), so the two overlap::

    warm = WarmUp.start(params, channels)   # right after the capture is opened
    state = prepare_sequence(src, recipe)   # the capture's pass, while torch imports
    warm.wait_precision()                   # before anything asks for the precision
    ...                                     # the plan's pooling, while the weights load
    warm.wait()                             # before the sampler runs

Everything here fills caches the run reads anyway (the same calls, the same results): a failure is
left for the run to meet and report in its own words, never raised from the thread.
"""

from __future__ import annotations

import threading
from typing import Any


class WarmUp:
    """One background start-up; :meth:`wait_precision` and :meth:`wait` block until its two phases end."""

    def __init__(self) -> None:
        self._precision = threading.Event()
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    @classmethod
    def start(cls, params: Any, channels: int) -> WarmUp:
        """Start warming the prior of ``params`` (a :class:`~spikeview.guided.GuidedConfig`) for ``channels`` (3 or 1)."""
        warm = cls()
        warm._thread = threading.Thread(target=warm._work, args=(params, channels), name="spikeview-warm-up", daemon=True)
        warm._thread.start()
        return warm

    def _work(self, params: Any, channels: int) -> None:
        try:
            from spikeview.guided.precision import resolve_precision

            resolve_precision(params.precision)  # imports torch, probes the CPU (cached for the run)
        except Exception:  # noqa: BLE001 - the run resolves it again and reports any failure itself
            pass
        finally:
            self._precision.set()
        try:
            if params.prior == "ffdnet":
                from spikeview.guided.priors import ov_backend
                from spikeview.guided.sampler import load_prior

                ov_backend.available()  # OpenVINO's one-time probe, cached (the plan's precision row asks first)
                load_prior(params, channels)  # the packaged (or given) weights, cached
        except Exception:  # noqa: BLE001 - e.g. missing weights: the sampler raises the clear error
            pass
        finally:
            self._done.set()

    def wait_precision(self) -> None:
        """Block until torch is imported and the precision resolved (the first phase)."""
        self._precision.wait()

    def wait(self) -> None:
        """Block until the whole start-up has ended."""
        self._done.wait()
