"""Fuzzing every reader with random, truncated and mutated bytes.

The only allowed outcomes are a working source (whose reads and counts succeed and agree) or a
:class:`~spikeview.errors.SpikeviewError`: never another exception, never a hang.
"""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from spikeview.errors import SpikeviewError
from spikeview.io import (
    NpySource,
    PlainDatSource,
    Raw1MDecoder,
    Raw1MSource,
    Raw400Source,
    encode_raw1m,
    encode_raw400,
    open_source,
    pack_frames,
)
from spikeview.io.raw1m import RAW1M_FRAME_BYTES, scan_raw1m

# a shared 2-core box: no per-example deadline (timings vary), a modest number of examples
FUZZ = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _rng_bytes(seed: int, n: int) -> bytes:
    return np.random.default_rng(seed).integers(0, 256, n, dtype=np.uint8).tobytes()


def _spikes(seed: int, t: int, h: int, w: int) -> np.ndarray:
    return (np.random.default_rng(seed).random((t, h, w)) < 0.4).astype(np.uint8)


def _npz_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, spikes=arr)
    return buf.getvalue()


def _npy_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


BASES = {
    ".dat": pack_frames(_spikes(1, 5, 8, 16)).tobytes(),
    ".r400": encode_raw400(_spikes(2, 2, 250, 400)),
    ".r1m": encode_raw1m(_spikes(3, 2, 1000, 1000)),
    ".npy": _npy_bytes(_spikes(4, 5, 8, 16)),
    ".npz": _npz_bytes(_spikes(5, 5, 8, 16)),
}

READERS = {
    "plain16x8": lambda p: PlainDatSource(p, 16, 8),
    "plain12x2": lambda p: PlainDatSource(p, 12, 2),  # rows not byte aligned
    "raw400": lambda p: Raw400Source(p),
    "raw1m": lambda p: Raw1MSource(p),
    "raw1m-lenient": lambda p: Raw1MSource(p, tag_check="lenient"),
    "npy": lambda p: NpySource(p),
    "open": lambda p: open_source(p),
    "open16x8": lambda p: open_source(p, width=16, height=8),
}


def _check_reader(make, path: Path) -> None:
    """Open with ``make``; a SpikeviewError is fine, anything else must be a working source."""
    try:
        src = make(path)
    except SpikeviewError:
        event("refused with SpikeviewError")
        return
    event("opened")
    with src:
        n, h, w = src.shape
        assert n >= 1 and h >= 1 and w >= 1
        try:
            first = src.read(0, min(n, 3))
            last = src.read(n - 1, n)
            counts = src.count(0, n)
        except SpikeviewError:  # e.g. array values checked as they are read
            return
        assert first.shape == (min(n, 3), h, w) and first.dtype == np.uint8 and first.max(initial=0) <= 1
        assert last.shape == (1, h, w)
        assert counts.shape == (h, w)
        if n * h * w <= 4_000_000:
            np.testing.assert_array_equal(counts, src.read(0, n).sum(axis=0))


def _with_file(data: bytes, suffix: str, fn) -> None:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"fuzz{suffix}"
        path.write_bytes(data)
        fn(path)


# ------------------------------------------------------------------------------- random bytes
@FUZZ
@given(data=st.binary(min_size=0, max_size=3000), suffix=st.sampled_from([".dat", ".bin", ".npy", ".npz"]),
       reader=st.sampled_from(sorted(READERS)))
def test_random_small_files(data, suffix, reader):
    _with_file(data, suffix, lambda p: _check_reader(READERS[reader], p))


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), size=st.integers(12_000, 300_000),
       reader=st.sampled_from(["plain16x8", "raw400", "raw1m", "raw1m-lenient", "open", "open16x8"]))
def test_random_large_files(seed, size, reader):
    _with_file(_rng_bytes(seed, size), ".bin", lambda p: _check_reader(READERS[reader], p))


# ---------------------------------------------------------------------- truncated / mutated
@st.composite
def mutated(draw):
    suffix = draw(st.sampled_from(sorted(BASES)))
    data = bytearray(BASES[suffix])
    cut = draw(st.one_of(st.none(), st.integers(0, len(data))))
    if cut is not None:
        del data[cut:]
    for _ in range(draw(st.integers(0, 4))):
        if not data:
            break
        pos = draw(st.integers(0, len(data) - 1))
        kind = draw(st.sampled_from(["flip", "insert", "delete"]))
        if kind == "flip":
            data[pos] ^= draw(st.integers(1, 255))
        elif kind == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=200))
        else:
            del data[pos:pos + draw(st.integers(1, 200))]
    return suffix, bytes(data)


MATCHING = {".dat": ["plain16x8", "open16x8"], ".r400": ["raw400", "open"], ".r1m": ["raw1m", "raw1m-lenient", "open"],
            ".npy": ["npy", "open"], ".npz": ["npy", "open"]}


@FUZZ
@given(case=mutated(), pick=st.integers(0, 2))
def test_truncated_and_mutated_files(case, pick):
    suffix, data = case
    names = MATCHING[suffix]
    reader = names[pick % len(names)]
    file_suffix = suffix if suffix in (".npy", ".npz", ".dat") else ".bin"
    _with_file(data, file_suffix, lambda p: _check_reader(READERS[reader], p))


# ---------------------------------------------------------------------------- raw1m decoder
@FUZZ
@given(case=mutated(), seed=st.integers(0, 2**32 - 1), min_chunk=st.sampled_from([1000, 20_000, 200_000]))
def test_decoder_never_fails_and_accounts_every_byte(case, seed, min_chunk):
    _, data = case
    rng = np.random.default_rng(seed)
    dec = Raw1MDecoder()
    n_frames, pos = 0, 0
    while pos < len(data):
        step = int(rng.integers(min_chunk, 2 * min_chunk))
        frames = dec.feed(data[pos:pos + step])
        assert frames.dtype == np.uint8 and frames.shape[1:] == (1000, 1000)
        n_frames += frames.shape[0]
        pos += step
    stats = dec.finish()
    assert stats.frames == n_frames
    assert n_frames * RAW1M_FRAME_BYTES + stats.leading_bytes + stats.skipped_bytes + stats.trailing_bytes == len(data)
    offsets, file_stats = scan_raw1m(np.frombuffer(data, np.uint8))
    assert file_stats == stats  # the file index and the live decoder agree
    assert offsets.size == n_frames


def test_decoder_with_tiny_chunks_stays_fast():
    data = b"\x13" * 5000 + BASES[".r1m"][: RAW1M_FRAME_BYTES + 3000]
    dec = Raw1MDecoder()
    got = [dec.feed(data[i:i + 7]) for i in range(0, len(data), 7)]
    stats = dec.finish()
    assert sum(g.shape[0] for g in got) == 1
    assert (stats.leading_bytes, stats.trailing_bytes) == (5000, 3000)


@pytest.mark.parametrize("suffix", sorted(BASES))
def test_unmodified_bases_open(tmp_path, suffix):
    # the fuzz bases themselves are valid: the mutations above start from working files
    path = tmp_path / f"base{suffix if suffix in ('.npy', '.npz', '.dat') else '.bin'}"
    path.write_bytes(BASES[suffix])
    src = READERS[MATCHING[suffix][0]](path)
    assert src.n_frames >= 2
