"""Readers and writers of spike files, sidecars and the :class:`SpikeSource` interface (numpy only).

Open anything with :func:`open_source`; write plain ``.dat`` files with :func:`write_plain` or,
streaming, :class:`PlainDatWriter`. numba (the fast packed counting) is imported only on first use.
"""

from spikeview.io.arrays import NpySource, write_array
from spikeview.io.geometry import GeometryGuess, rank_plain_geometries, rate_warnings
from spikeview.io.open import UNSET, open_source, plain_geometry_candidates
from spikeview.io.plain import PlainDatSource, PlainDatWriter, pack_frames, write_plain
from spikeview.io.raw1m import (
    Raw1MDecoder,
    Raw1MSource,
    SyncStats,
    decode_raw1m_frames,
    encode_raw1m,
    raw1m_tag_sequence,
    write_raw1m,
)
from spikeview.io.raw400 import Raw400Source, encode_raw400, write_raw400
from spikeview.io.sidecar import Sidecar, StreamSettings, read_sidecar, sidecar_path, write_sidecar
from spikeview.io.source import DEFAULT_TICK_RATE, FORMATS, ArraySource, SpikeSource, StreamInfo

__all__ = [
    "DEFAULT_TICK_RATE",
    "FORMATS",
    "GeometryGuess",
    "UNSET",
    "ArraySource",
    "NpySource",
    "PlainDatSource",
    "PlainDatWriter",
    "Raw1MDecoder",
    "Raw1MSource",
    "Raw400Source",
    "Sidecar",
    "SpikeSource",
    "StreamInfo",
    "StreamSettings",
    "SyncStats",
    "decode_raw1m_frames",
    "encode_raw1m",
    "encode_raw400",
    "open_source",
    "pack_frames",
    "plain_geometry_candidates",
    "rank_plain_geometries",
    "rate_warnings",
    "raw1m_tag_sequence",
    "read_sidecar",
    "sidecar_path",
    "write_array",
    "write_plain",
    "write_raw1m",
    "write_raw400",
    "write_sidecar",
    "warm_up_counting",
]


def warm_up_counting() -> None:
    """Load numba's packed-frame counting kernel in the calling thread, for the argument types file sources
    pass (:func:`spikeview.io._packed.warm_up`): the app's window does it before its workers start, so a first
    file open does not stall the window while a worker loads it under the interpreter lock."""
    from spikeview.io._packed import warm_up  # numba: imported here, on first use only

    warm_up()
