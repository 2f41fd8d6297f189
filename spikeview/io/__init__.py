"""Readers and writers of spike files, sidecars and the :class:`SpikeSource` interface (numpy only)."""

from spikeview.io.source import DEFAULT_TICK_RATE, FORMATS, ArraySource, SpikeSource, StreamInfo

__all__ = ["DEFAULT_TICK_RATE", "FORMATS", "ArraySource", "SpikeSource", "StreamInfo"]
