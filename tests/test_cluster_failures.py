"""A batch run that fails leaves a resumable store or nothing, never one that ``export`` reads as complete,
and the batch edges answer in one sentence (issues 14 and 18).

Failures are injected where the work goes (the chunk writer, the store's creation, the frames of a
chunk); monochrome and Bayer captures both.
"""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")
zarr = pytest.importorskip("zarr")

from spikeview.cli.main import main  # noqa: E402
from spikeview.io.plain import write_plain  # noqa: E402

RUN = ["--window", "4", "--range", "2:42:4"]  # 10 windows
LONG = ["--window", "16", "--range", "8:40:8"]  # windows long enough for a white point below full count


@pytest.fixture(params=["RGGB", "none"])
def cap(tmp_path, request):
    rng = np.random.default_rng(2)
    src = tmp_path / "in" / "c.dat"
    src.parent.mkdir()
    write_plain(src, (rng.random((48, 16, 16)) < 0.4).astype(np.uint8))
    return [str(src), "--width", "16", "--height", "16", "--cfa", request.param]


def _err(capsys, *needles: str) -> str:
    err = capsys.readouterr().err.strip()
    lines = [ln for ln in err.splitlines() if ln.startswith("spikeview: error:")]
    assert len(lines) == 1 and err.endswith(lines[0]), err
    assert "this is a bug" not in err and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], err
    return lines[0]


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def _enospc(*_a, **_k):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_full_disk_on_the_first_chunk_leaves_nothing(cap, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("spikeview.cluster.store.write_chunk", _enospc)
    assert main(["reconstruct", *cap, *RUN, "--chunk", "4", "--out", str(tmp_path / "s.zarr")]) == 1
    _err(capsys, "s.zarr", "disk is full")
    assert _names(tmp_path) == ["in"]  # no store, no preset


def test_full_disk_later_leaves_a_resumable_store_that_export_refuses(cap, tmp_path, capsys, monkeypatch):
    from spikeview.cluster import store as store_mod

    real, calls = store_mod.write_chunk, []

    def second_fails(*a, **k):
        calls.append(1)
        return _enospc() if len(calls) == 2 else real(*a, **k)

    monkeypatch.setattr(store_mod, "write_chunk", second_fails)
    out = tmp_path / "s.zarr"
    assert main(["reconstruct", *cap, *RUN, "--chunk", "4", "--out", str(out)]) == 1
    _err(capsys, "s.zarr", "disk is full", "--resume")
    assert list(zarr.open_group(str(out))["done"][:]) == [1, 0, 0]
    assert main(["export", str(out), "--out", str(tmp_path / "o.npy")]) == 1
    _err(capsys, "incomplete (1 of 3 chunks done)", "--resume")
    monkeypatch.setattr(store_mod, "write_chunk", real)
    assert main(["reconstruct", *cap, "--out", str(out), "--resume"]) == 0
    assert main(["export", str(out), "--out", str(tmp_path / "o.npy")]) == 0


def test_full_disk_while_the_store_is_created_leaves_nothing(cap, tmp_path, capsys, monkeypatch):
    from spikeview.cluster import store as store_mod

    real = store_mod.create_store

    def half(path, **k):
        real(path, **k)
        _enospc()

    monkeypatch.setattr(store_mod, "create_store", half)
    assert main(["reconstruct", *cap, *RUN, "--out", str(tmp_path / "s.zarr")]) == 1
    _err(capsys, "s.zarr", "disk is full")
    assert _names(tmp_path) == ["in"]


@pytest.mark.parametrize(("exc", "code"), [(KeyboardInterrupt, 130), (MemoryError, 1)], ids=["interrupt", "out_of_memory"])
def test_a_chunk_stopped_before_it_is_done_leaves_nothing(cap, tmp_path, capsys, monkeypatch, exc, code):
    def stopped(*a, **k):
        raise exc

    monkeypatch.setattr("spikeview.cluster.run.compute_chunk", stopped)
    assert main(["reconstruct", *cap, *RUN, "--out", str(tmp_path / "s.zarr")]) == code
    if exc is KeyboardInterrupt:
        assert "interrupted" in capsys.readouterr().err
    else:
        _err(capsys, "out of memory")
    assert _names(tmp_path) == ["in"]


def test_a_huge_chunk_is_one_chunk_of_the_whole_run(cap, tmp_path, capsys):
    out = tmp_path / "s.zarr"
    assert main(["reconstruct", *cap, *RUN, "--chunk", "1000000000", "--out", str(out)]) == 0
    g = zarr.open_group(str(out))
    assert g.attrs["spikeview"]["chunk"] == 10 and g["frames"].chunks[0] == 10 and list(g["done"][:]) == [1]
    # resuming with the same flag agrees with the store
    assert main(["reconstruct", *cap, *RUN, "--chunk", "1000000000", "--out", str(out), "--resume"]) == 0


def test_a_chunk_larger_than_memory_is_refused_before_any_work(cap, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("spikeview.cluster.reconstruct._available_memory", lambda: 10_000)
    assert main(["reconstruct", *cap, *RUN, "--chunk", "8", "--out", str(tmp_path / "s.zarr")]) == 1
    _err(capsys, "--chunk 8", "memory", "smaller --chunk")
    assert _names(tmp_path) == ["in"]


def test_resume_of_a_store_that_does_not_exist(cap, tmp_path, capsys):
    assert main(["reconstruct", *cap, *RUN, "--out", str(tmp_path / "s.zarr"), "--resume"]) == 1
    _err(capsys, "s.zarr does not exist", "leave --resume out")
    assert _names(tmp_path) == ["in"]


def test_read_only_target(cap, tmp_path, capsys, monkeypatch):
    import os

    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **k: False if Path(p) == ro else real(p, mode, **k))
    assert main(["reconstruct", *cap, *RUN, "--out", str(ro / "s.zarr")]) == 1
    _err(capsys, "read-only", "--out")
    assert _names(ro) == []
    # a file system that refuses the write itself (EROFS) says the same kind of sentence

    def erofs(*a, **k):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr("spikeview.cluster.store.create_store", erofs)
    assert main(["reconstruct", *cap, *RUN, "--out", str(tmp_path / "s.zarr")]) == 1
    _err(capsys, "s.zarr", "no permission to write there")
    assert _names(tmp_path) == ["in", "ro"]


def test_out_naming_a_folder(cap, tmp_path, capsys):
    store = tmp_path / "s.zarr"
    assert main(["reconstruct", *cap, *RUN, "--out", str(store)]) == 0
    for name in ("d.npy", "d.mp4"):
        (tmp_path / name).mkdir()
        assert main(["export", str(store), "--out", str(tmp_path / name)]) == 1
        _err(capsys, "is a folder; give a file name")
        assert main(["reconstruct", *cap, "--at", "20", "--out", str(tmp_path / name)]) == 1
        _err(capsys, "is a folder; give a file name")
    (tmp_path / "e.zarr").mkdir()
    assert main(["reconstruct", *cap, *RUN, "--out", str(tmp_path / "e.zarr")]) == 1
    _err(capsys, "e.zarr already exists")


def test_store_frames_are_linear_and_export_equals_a_plain_npy_run(cap, tmp_path):
    """The store keeps linear frames (values above 1 kept) and the white point as an attribute;
    ``spikeview export`` maps them as a plain run does: the .npy files are identical."""
    store = tmp_path / "s.zarr"
    assert main(["reconstruct", *cap, *LONG, "--out", str(store)]) == 0
    assert main(["export", str(store), "--out", str(tmp_path / "e.npy")]) == 0
    assert main(["reconstruct", *cap, *LONG, "--out", str(tmp_path / "p.npy")]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "e.npy"), np.load(tmp_path / "p.npy"))
    g = zarr.open_group(str(store))
    white = g.attrs["spikeview"]["white_point"]
    frames = np.asarray(g["frames"][:])
    expected = np.clip(frames / np.float32(white), 0, 1)
    np.testing.assert_allclose(np.load(tmp_path / "e.npy").reshape(expected.shape), expected, rtol=1e-6)
    assert white != 1.0 and not np.allclose(frames, expected)  # the store is not the bounded output


def test_absurd_local_cluster_is_refused_before_any_work(cap, tmp_path, capsys, monkeypatch):
    def no_workers(*a, **k):
        raise AssertionError("99999 workers were about to start")

    monkeypatch.setattr("distributed.LocalCluster", no_workers)
    assert main(["reconstruct", *cap, *RUN, "--cluster", "local:99999", "--out", str(tmp_path / "s.zarr")]) == 1
    _err(capsys, "local:99999", "cores")
    assert _names(tmp_path) == ["in"]


def test_a_store_in_a_missing_folder(cap, tmp_path, capsys):
    assert main(["reconstruct", *cap, *RUN, "--out", str(tmp_path / "nosuch" / "s.zarr")]) == 1
    _err(capsys, "the folder", "does not exist")
    assert _names(tmp_path) == ["in"]
