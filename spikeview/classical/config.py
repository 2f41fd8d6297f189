"""The classical settings (:class:`ClassicalConfig`); they live in :mod:`spikeview.classical_config`,
outside this package, so the CLI can build its flags without importing numba."""

from spikeview.classical_config import (  # noqa: F401
    CLASSICAL_METHODS,
    DEFAULT_ALPHA_WINDOWS,
    DEFAULT_ETA,
    DEFAULT_HALF_WINDOW,
    DEMOSAICS,
    ClassicalConfig,
)
