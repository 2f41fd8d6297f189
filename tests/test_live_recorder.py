"""The recorder: a writer thread that never blocks acquisition, counts what it drops, and always finalises."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest

from spikeview.errors import OutputFileError, ParameterError
from spikeview.io import PlainDatWriter, open_source, pack_frames, read_sidecar
from spikeview.live.recorder import Recorder

WAIT_S = 30


def packed(start: int, n: int, h: int = 8, w: int = 16) -> np.ndarray:
    """Frames whose pixels spell their index (bits of ``t`` repeated), packed: distinct and checkable."""
    t = np.arange(start, start + n)
    bits = ((t[:, None] >> np.arange(h * w) % 12) & 1).astype(np.uint8).reshape(n, h, w)
    return pack_frames(bits, flip_vertical=False)


def test_frames_are_written_in_order_with_the_sidecar(tmp_path):
    rec = Recorder(tmp_path / "a.dat", 16, 8, cfa="RGGB", tick_rate=1000.0, tables={"recording": {"source": "test"}})
    for i in range(0, 30, 3):
        assert rec.submit(packed(i, 3))
    summary = rec.stop(timeout=WAIT_S)
    assert (summary.state, summary.frames, summary.buffer_dropped_frames) == ("done", 30, 0)
    assert (tmp_path / "a.dat").read_bytes() == packed(0, 30).tobytes()
    side = read_sidecar(tmp_path / "a.dat")
    assert side.stream.cfa == "RGGB" and side.stream.tick_rate == 1000.0
    table = side.tables["recording"]
    assert (table["source"], table["frames"], table["state"], table["end"]) == ("test", 30, "complete", "stopped by the user")
    with open_source(tmp_path / "a.dat") as src:
        assert src.n_frames == 30


def test_a_slow_disk_never_blocks_submit_and_overflow_is_counted(tmp_path, monkeypatch):
    gate = threading.Event()
    real = PlainDatWriter.write_packed

    def slow_write(self, data):
        assert gate.wait(WAIT_S), "test gate never opened"
        real(self, data)

    monkeypatch.setattr(PlainDatWriter, "write_packed", slow_write)
    fb = 16  # bytes per 8×16 frame
    rec = Recorder(tmp_path / "slow.dat", 16, 8, max_queue_bytes=5 * fb)
    accepted = []
    for i in range(20):  # the writer is stuck on the first batch; the queue holds 5 frames more
        if rec.submit(packed(i, 1)):
            accepted.append(i)
    assert rec.buffer_dropped_frames == 20 - len(accepted) > 0
    assert 5 <= len(accepted) <= 6  # one batch may already be with the writer
    gate.set()
    summary = rec.stop(timeout=WAIT_S)
    assert summary.frames == len(accepted)
    assert (tmp_path / "slow.dat").read_bytes() == np.concatenate([packed(i, 1) for i in accepted]).tobytes()
    table = read_sidecar(tmp_path / "slow.dat").tables["recording"]
    assert table["buffer_dropped_frames"] == summary.buffer_dropped_frames
    assert "could not keep up" in summary.message


def test_a_failing_disk_is_reported_and_the_file_stays_readable(tmp_path, monkeypatch):
    real = PlainDatWriter.write_packed
    calls = {"n": 0}

    def failing(self, data):
        calls["n"] += 1
        if calls["n"] > 2:
            raise OutputFileError(f"{self.path}: write failed (No space left on device); check free disk space.")
        real(self, data)

    monkeypatch.setattr(PlainDatWriter, "write_packed", failing)
    rec = Recorder(tmp_path / "full.dat", 16, 8)
    for i in range(5):
        rec.submit(packed(i, 1))
    summary = rec.stop(timeout=WAIT_S)
    assert summary.state == "failed" and "No space left" in summary.message
    assert summary.frames == 2 and summary.buffer_dropped_frames == 3
    table = read_sidecar(tmp_path / "full.dat").tables["recording"]
    assert table["state"] == "failed" and "No space left" in table["error"]
    with open_source(tmp_path / "full.dat") as src:
        assert src.n_frames == 2


def test_stop_is_idempotent_and_later_frames_are_counted(tmp_path):
    rec = Recorder(tmp_path / "b.dat", 16, 8)
    rec.submit(packed(0, 2))
    first = rec.stop("device gone", timeout=WAIT_S)
    assert not rec.submit(packed(2, 1))
    second = rec.stop("again", timeout=WAIT_S)
    assert first.frames == second.frames == 2
    assert read_sidecar(tmp_path / "b.dat").tables["recording"]["end"] == "device gone"
    assert rec.buffer_dropped_frames == 1


def test_bad_input_and_existing_files(tmp_path):
    (tmp_path / "x.dat").write_bytes(b"")
    with pytest.raises(OutputFileError, match="exists"):
        Recorder(tmp_path / "x.dat", 16, 8)
    with pytest.raises(OutputFileError, match="does not exist"):
        Recorder(tmp_path / "missing" / "x.dat", 16, 8)
    (tmp_path / "replayed.dat").write_bytes(b"the capture being replayed")
    with pytest.raises(OutputFileError, match="input of the run.*even with --overwrite"):
        Recorder(tmp_path / "replayed.dat", 16, 8, overwrite=True, inputs=[tmp_path / "replayed.dat"])
    assert (tmp_path / "replayed.dat").read_bytes() == b"the capture being replayed"
    rec = Recorder(tmp_path / "x.dat", 16, 8, overwrite=True)
    with pytest.raises(ParameterError, match=r"\(n, 16\)"):
        rec.submit(np.zeros((1, 15), np.uint8))
    rec.stop(timeout=WAIT_S)


def test_leaving_python_finalises_a_running_recording(tmp_path):
    """A script that forgets to stop its camera: the exit hook stops it and the file is complete."""
    path = tmp_path / "exit.dat"
    code = textwrap.dedent(f"""
        import numpy as np
        from spikeview.io import ArraySource
        from spikeview.live import SimCamera
        x = (np.arange(40 * 8 * 16).reshape(40, 8, 16) % 3 == 0).astype(np.uint8)
        cam = SimCamera(ArraySource(x), slowdown=2000, chunk_ticks=1)
        cam.start_recording({str(path)!r})
        cam.start()
        assert cam.wait_frames(3, 30)
        print("frames", cam.n_frames)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    table = read_sidecar(path).tables["recording"]
    assert table["state"] == "complete" and table["frames"] >= 3
    with open_source(path) as src:
        n = src.n_frames
        assert n == table["frames"]
        x = (np.arange(40 * 8 * 16).reshape(40, 8, 16) % 3 == 0).astype(np.uint8)
        np.testing.assert_array_equal(src.read(0, n), x[np.arange(n) % 40])
