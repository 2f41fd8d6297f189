"""npy stacks and their TOML sidecars."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.config import load_toml
from spikeview.errors import Cancelled, ParameterError
from spikeview.export import ExportConfig, ExportMetadata, export_frames, open_exporter, read_export_metadata
from spikeview.export.atomic import PARTIAL_MARKER

H, W = 32, 48


def frames(n, mono=False, seed=3):
    rng = np.random.default_rng(seed)
    return rng.random((n, H, W) if mono else (n, H, W, 3), dtype=np.float32)


def test_npy_values_shape_and_sidecar(tmp_path):
    x = frames(4)
    x[0, 0, 0] = [1.25, 0.0, 0.5]  # linear values are stored as given, not clipped
    meta = ExportMetadata(
        source="c.dat",
        method="tfp",
        tick_rate=40_000.0,
        window=(5, 15),
        centre_tick=10,
        step_ticks=20,
        params={"alpha": [1.0, 0.8, 1.3]},
    )
    written = export_frames(x, tmp_path / "stack.npy", ExportConfig(), meta)
    assert [p.name for p in written] == ["stack.npy", "stack.npy.toml"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stack.npy", "stack.npy.toml"]
    y = np.load(tmp_path / "stack.npy")
    assert y.dtype == np.float32 and y.shape == (4, H, W, 3)
    np.testing.assert_array_equal(y, x)
    side = load_toml(tmp_path / "stack.npy.toml")
    assert side == read_export_metadata(tmp_path / "stack.npy")
    assert side["n_frames"] == 4 and side["shape"] == [4, H, W, 3] and side["dtype"] == "float32"
    assert side["source"] == "c.dat" and side["method"] == "tfp" and side["tick_rate"] == 40_000.0
    assert side["params"] == {"alpha": [1.0, 0.8, 1.3]}
    assert [f["window"] for f in side["frames"]] == [[5, 15], [25, 35], [45, 55], [65, 75]]
    assert [f["centre_tick"] for f in side["frames"]] == [10, 30, 50, 70]


def test_npy_mono(tmp_path):
    x = frames(2, mono=True)
    export_frames(x, tmp_path / "mono.npy")
    y = np.load(tmp_path / "mono.npy")
    assert y.shape == (2, H, W)
    np.testing.assert_array_equal(y, x)


def test_npy_cancel_keeps_the_finished_frames(tmp_path):
    x = frames(5)
    with pytest.raises(Cancelled):
        with open_exporter(tmp_path / "s.npy", 5, (H, W, 3), cancel=lambda: ex.frames_written == 2) as ex:
            for f in x:
                ex.write(f)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.npy", "s.npy.toml"]
    y = np.load(tmp_path / "s.npy")
    assert y.shape == (2, H, W, 3)
    np.testing.assert_array_equal(y, x[:2])
    assert load_toml(tmp_path / "s.npy.toml")["n_frames"] == 2


def test_npy_error_leaves_nothing(tmp_path):
    bad = frames(3)
    bad[2, 1, 1, 1] = np.nan
    with pytest.raises(ParameterError, match="frame 2 has 1 NaN"):
        export_frames(bad, tmp_path / "s.npy")
    assert list(tmp_path.iterdir()) == []


def test_npy_short_close_is_an_error_and_the_exporter_stays_usable(tmp_path):
    x = frames(2)
    ex = open_exporter(tmp_path / "s.npy", 2, (H, W, 3))
    ex.write(x[0])
    with pytest.raises(ParameterError, match="only 1 of 2 frames"):
        ex.close()
    ex.write(x[1])
    assert [p.name for p in ex.close()] == ["s.npy", "s.npy.toml"]
    np.testing.assert_array_equal(np.load(tmp_path / "s.npy"), x)
    assert not any(PARTIAL_MARKER in p.name for p in tmp_path.iterdir())


def test_large_npy_exports_announce_their_size_and_reserve_it(tmp_path, monkeypatch):
    import spikeview._files as files
    from spikeview.export import open_exporter

    monkeypatch.setattr(files, "LARGE_WRITE_BYTES", 10_000)
    said = []
    ex = open_exporter(tmp_path / "big.npy", 4, (32, 32, 3), announce=said.append)
    # 4 frames · 32·32·3 · 4 bytes + the 128-byte header = 49,280 bytes, reserved before the first frame
    assert said == ["writing big.npy: 4 float32 frames, 49.3 KB"]
    tmp = ex._file.tmp
    assert tmp.stat().st_size == 49_280
    ex.abort()
    assert not tmp.exists() and not list(tmp_path.iterdir())
