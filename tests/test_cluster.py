"""The chunked, resumable batch path: ``spikeview reconstruct … --out OUT.zarr`` and ``spikeview export``.

Tiny captures (32×32, a few windows); one shared two-process LocalCluster for the Dask cases (its
scheduler address also exercises ``--cluster tcp://…``), one CLI run that starts its own ``local:2``.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")
zarr = pytest.importorskip("zarr")

from spikeview.cli.main import main  # noqa: E402
from spikeview.errors import Cancelled  # noqa: E402
from spikeview.io.plain import write_plain  # noqa: E402

GEOM = ["--width", "32", "--height", "32", "--cfa", "RGGB"]
GUIDED = ["--method", "guided", "--steps", "2", "--seed", "5"]


def _capture(path, seed=7, ticks=240):
    rng = np.random.default_rng(seed)
    ramp = np.linspace(0.05, 0.9, 32, dtype=np.float32)[None, None, :]
    spikes = (rng.random((ticks, 32, 32)) < ramp).astype(np.uint8)
    spikes[ticks // 2:, 8:16, 8:16] = 1  # a change half-way: guided reuse and re-sampling both happen
    write_plain(path, spikes)
    return path


@pytest.fixture
def cap(tmp_path):
    return _capture(tmp_path / "cap.dat")


@pytest.fixture(scope="module")
def cluster():
    """Two single-threaded worker processes, shared by the Dask tests of this module."""
    from distributed import Client, LocalCluster

    lc = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=40)
    client = Client(lc)
    yield lc, client
    client.close()
    lc.close()


def _frames(store):
    g = zarr.open_group(str(store), mode="r")
    assert np.asarray(g["done"][:]).all()
    return np.asarray(g["frames"][:])


def _mapped(store):
    """The store's linear frames as the .npy output holds them (divided by the white point, clipped)."""
    import tomllib

    from spikeview.cluster._compute import state_from_attrs
    from spikeview.cluster.store import open_store, store_attrs
    from spikeview.pipeline import exposure_mapping
    from spikeview.recipe import Recipe

    attrs = store_attrs(open_store(store))
    recipe = Recipe.from_dict(tomllib.loads(attrs["recipe"]))
    expose = exposure_mapping(recipe, state_from_attrs(attrs), "x.npy")[1]
    frames = _frames(store)
    return np.stack([expose(f) for f in frames])


def _reconstruct(*argv) -> int:
    return main(["reconstruct", *map(str, argv)])


# ------------------------------------------------------------------------------ bit identity
def test_tfp_chunk3_on_local2_matches_in_process_and_file_output(cap, tmp_path, capsys):
    common = [cap, *GEOM, "--range", "5:200:10"]
    assert _reconstruct(*common, "--out", tmp_path / "a.zarr") == 0
    assert _reconstruct(*common, "--out", tmp_path / "b.zarr", "--chunk", "3", "--cluster", "local:2") == 0
    assert _reconstruct(*common, "--out", tmp_path / "ref.npy") == 0
    a, b = _frames(tmp_path / "a.zarr"), _frames(tmp_path / "b.zarr")
    assert a.shape == (20, 32, 32, 3) and a.dtype == np.float32 and np.isfinite(a).all()
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(_mapped(tmp_path / "a.zarr"), np.load(tmp_path / "ref.npy"))  # the file path: same frames
    g = zarr.open_group(str(tmp_path / "b.zarr"), mode="r")
    assert g["frames"].chunks == (3, 32, 32, 3)
    np.testing.assert_array_equal(g["centre_tick"][:], np.arange(5, 200, 10))
    np.testing.assert_array_equal(g["window"][:2], [[0, 10], [10, 20]])
    meta = g.attrs["spikeview"]
    assert meta["method"] == "tfp" and len(meta["alpha"]) == 3 and "[classical]" in meta["recipe"]
    assert "alpha" not in meta["settings"]["classical"]  # as given: the estimate is state, not a setting
    assert "alpha = [" in meta["recipe"]  # the estimate is recorded: the recipe reproduces it
    assert isinstance(meta["white_point"], float) and meta["white_point"] > 0  # computed once, before the split
    err = capsys.readouterr().err
    assert "20 windows in 7 chunks of 3 (tfp, on local:2)" in err and "windows/s" in err


def test_guided_chunk3_on_scheduler_address_matches_in_process(cap, tmp_path, cluster):
    _, client = cluster
    common = [cap, *GEOM, *GUIDED, "--range", "5:240:40"]  # 6 windows: reuse chain across the chunk border
    assert _reconstruct(*common, "--out", tmp_path / "a.zarr") == 0
    assert _reconstruct(*common, "--out", tmp_path / "b.zarr", "--chunk", "4",
                        "--cluster", client.scheduler.address) == 0
    a, b = _frames(tmp_path / "a.zarr"), _frames(tmp_path / "b.zarr")
    assert a.shape == (6, 32, 32, 3) and np.isfinite(a).all()
    np.testing.assert_array_equal(a, b)
    # each worker opened the input once, however many chunks it ran
    opens = client.run(lambda: __import__("spikeview.cluster._compute", fromlist=["OPENS"]).OPENS.get(str(cap), 0))
    assert set(opens.values()) <= {0, 1} and sum(opens.values()) >= 1
    # with the default chunk (16 >= 6 windows) the store equals one plain sequence run
    assert _reconstruct(*common, "--out", tmp_path / "ref.npy") == 0
    np.testing.assert_array_equal(_mapped(tmp_path / "a.zarr"), np.load(tmp_path / "ref.npy"))


def test_second_chunk_depends_on_its_lead_in(cap):
    """Windows 4-5 reuse / re-sample from window 3 (region mode): computed without the lead-in from the
    keyframe they differ, which is why a chunk starting between keyframes recomputes it."""
    from spikeview.cluster._compute import compute_chunk, prepare_state
    from spikeview.io import open_source
    from spikeview.recipe import Recipe

    recipe = Recipe().with_values({"run.method": "guided", "guided.steps": 2, "guided.seed": 5}).to_dict()
    centres = list(range(5, 240, 40))
    with open_source(cap, width=32, height=32, cfa="RGGB") as src:
        state = prepare_state(src, recipe)
        chained = compute_chunk(src, centres, recipe, state)[4:]
        alone = compute_chunk(src, centres[4:], recipe, state)
    assert not np.array_equal(chained, alone)


@pytest.mark.parametrize("method, first", [("tfp", 15), ("guided", 0)])
def test_a_task_carries_only_its_windows_and_lead_in(method, first):
    from spikeview.cluster.run import BatchJob

    job = BatchJob(input="x", open_kwargs={}, recipe={"run": {"method": method}}, centres=tuple(range(5, 405, 10)),
                   chunk=3, store="s")
    sub = job.for_chunk(5)  # windows 15-17; a guided chain restarts at the keyframe 0
    assert (sub.offset, sub.total, sub.n_chunks, sub.bounds(5)) == (first, 40, 14, (15, 18))
    assert sub.centres == job.centres[first:18]
    assert job.for_chunk(13).centres[-1] == 395  # the last, short chunk (window 39)


def test_killed_worker_is_retried_and_the_run_completes(cap, tmp_path, cluster):
    from spikeview.cli import batch

    _, client = cluster
    common = [cap, *GEOM, "--range", "5:200:10"]
    assert _reconstruct(*common, "--out", tmp_path / "ref.zarr") == 0
    pids = sorted(client.run(os.getpid).values())
    killed = []

    class Kill:
        def __call__(self) -> bool:  # polled after each finished chunk
            if not killed:
                os.kill(pids[0], signal.SIGKILL)
                killed.append(pids[0])
            return False

    from spikeview.cli.main import build_parser

    p = build_parser()
    args = p.parse_args(["reconstruct", *map(str, common), "--out", str(tmp_path / "k.zarr"), "--chunk", "1"])
    assert batch.run_zarr(args, cancel=Kill(), client=client) == 0
    assert killed
    np.testing.assert_array_equal(_frames(tmp_path / "k.zarr"), _frames(tmp_path / "ref.zarr"))
    client.wait_for_workers(2, timeout=60)  # the nanny restarts it for the next test


def test_progress_counts_windows_inside_chunks(cap, tmp_path, cluster):
    """Progress moves window by window, in-process and from Dask workers (their events), and never goes back."""
    from spikeview.cluster import run as run_mod
    from spikeview.cluster.reconstruct import reconstruct_to_store
    from spikeview.recipe import Recipe

    _, client = cluster
    recipe = Recipe().with_values({"run.range": "5:125:10", "stream.width": 32, "stream.height": 32,
                                   "stream.cfa": "RGGB"})
    seen: list[tuple[int, int]] = []
    reconstruct_to_store(cap, recipe, tmp_path / "p.zarr", chunk=4, progress=lambda d, t: seen.append((d, t)))
    assert [d for d, _ in seen] == list(range(13)) and {t for _, t in seen} == {12}
    client.run(lambda: setattr(__import__("spikeview.cluster.run", fromlist=["x"]), "EVENT_INTERVAL", 0.0))
    seen.clear()
    rep = reconstruct_to_store(cap, recipe, tmp_path / "q.zarr", chunk=4, client=client,
                               progress=lambda d, t: seen.append((d, t)))
    done = [d for d, _ in seen]
    assert done[0] == 0 and done[-1] == 12 and done == sorted(set(done))
    events = [msg for _, msg in client.get_events(rep.topic)]
    assert sorted({e["done"] for e in events}) == [1, 2, 3]  # each chunk of 4 reported windows 1-3, then its result
    client.run(lambda: setattr(__import__("spikeview.cluster.run", fromlist=["x"]), "EVENT_INTERVAL", run_mod.EVENT_INTERVAL))


# ----------------------------------------------------------------------------------- resume
def test_resume_after_an_interrupted_run_gives_identical_frames(cap, tmp_path):
    from spikeview.cli import batch
    from spikeview.cli.main import build_parser

    common = [str(cap), *GEOM, "--range", "5:200:10", "--chunk", "4"]
    assert _reconstruct(*common, "--out", tmp_path / "full.zarr") == 0
    out = tmp_path / "part.zarr"
    calls = []

    def cancel_after_two() -> bool:
        calls.append(1)
        return len(calls) >= 2

    args = build_parser().parse_args(["reconstruct", *common, "--out", str(out)])
    with pytest.raises(Cancelled):
        batch.run_zarr(args, cancel=cancel_after_two)
    g = zarr.open_group(str(out), mode="r+")
    assert list(g["done"][:]) == [1, 1, 0, 0, 0]
    assert np.isnan(g["frames"][8:]).all()
    g["frames"][8:12] = 7.0  # a chunk whose worker died after writing frames but before its marker
    assert _reconstruct(*common, "--out", out) == 1  # exists: --resume needed
    assert _reconstruct(cap, *GEOM, "--out", out, "--resume") == 0  # settings come from the store
    np.testing.assert_array_equal(_frames(out), _frames(tmp_path / "full.zarr"))


def test_resume_after_the_process_was_killed(cap, tmp_path):
    """A real ``kill -9`` of ``spikeview reconstruct`` part-way, then ``--resume``: the same frames as one run."""
    import subprocess
    import sys
    import time

    out = tmp_path / "killed.zarr"
    argv = [sys.executable, "-m", "spikeview", "reconstruct", str(cap), *GEOM, "--range", "5:125:1", "--chunk", "1",
            "--out", str(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    try:
        deadline = time.monotonic() + 120
        done = 0
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                done = int(np.asarray(zarr.open_group(str(out), mode="r")["done"][:]).sum())
            except Exception:  # the store is still being created
                done = 0
            if done >= 3:
                break
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL, "the run finished before it could be killed"
    marked = np.asarray(zarr.open_group(str(out), mode="r")["done"][:])
    assert 3 <= marked.sum() < marked.size
    assert _reconstruct(cap, *GEOM, "--out", out, "--resume") == 0
    assert _reconstruct(cap, *GEOM, "--range", "5:125:1", "--chunk", "8", "--out", tmp_path / "one.zarr") == 0
    np.testing.assert_array_equal(_frames(out), _frames(tmp_path / "one.zarr"))


@pytest.mark.parametrize("change, needle", [
    (["--window", "12"], "was written with other settings (classical.window = 10 there, 12 now)"),
    (["--chunk", "5"], "was written in chunks of 4 windows, not 5"),
    (["--other-input"], "belongs to another input"),
])
def test_resume_refuses_a_store_of_other_settings_or_input(cap, tmp_path, capsys, change, needle):
    out = tmp_path / "s.zarr"
    assert _reconstruct(cap, *GEOM, "--range", "5:100:10", "--chunk", "4", "--out", out) == 0
    src = cap
    if change == ["--other-input"]:
        src, change = _capture(tmp_path / "other.dat", seed=8), []
    capsys.readouterr()
    assert _reconstruct(src, *GEOM, "--range", "5:100:10", "--out", out, "--resume", *change) == 1
    err = capsys.readouterr().err.strip()
    assert needle in err and err.count("\n") == 0 and "Traceback" not in err


def test_bad_cluster_and_flag_errors_are_one_sentence(cap, tmp_path, capsys):
    cases = [
        (["--cluster", "tcp://127.0.0.1:9", "--out", tmp_path / "x.zarr"],
         "cannot reach a Dask scheduler at tcp://127.0.0.1:9 within 10 s (ConnectionRefusedError)"),
        (["--cluster", "lokal:2", "--out", tmp_path / "x.zarr"], "neither local:N nor a scheduler address"),
        (["--cluster", "local:0", "--out", tmp_path / "x.zarr"], "local:N needs a whole number"),
        (["--chunk", "3", "--out", tmp_path / "x.npy"], "end --out with .zarr"),
        (["--chunk", "0", "--out", tmp_path / "x.zarr"], "--chunk 0"),
    ]
    for extra, needle in cases:
        assert _reconstruct(cap, *GEOM, "--range", "5:50:10", *extra) == 1
        err = capsys.readouterr().err.strip()
        assert needle in err and "Traceback" not in err and err.count("\n") == 0, err
    assert not (tmp_path / "x.zarr").exists()


# ----------------------------------------------------------------------------------- export
def test_export_store_to_npy_and_mp4_with_the_stores_settings(cap, tmp_path, capsys):
    store = tmp_path / "c.zarr"
    assert _reconstruct(cap, *GEOM, "--range", "5:100:10", "--fps", "24", "--out", store) == 0
    assert main(["export", str(store), "--out", str(tmp_path / "f.npy")]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "f.npy"), _mapped(store))
    assert main(["export", str(store), "--out", str(tmp_path / "c.mp4")]) == 0
    assert (tmp_path / "c.mp4").stat().st_size > 0
    assert "at 24 fps" in capsys.readouterr().err  # the recipe's export settings
    from spikeview.export import read_export_metadata

    rec = read_export_metadata(tmp_path / "f.npy")
    assert rec["method"] == "tfp" and rec["params"]["classical"]["window"] == 10
    # the preset written beside the export re-runs the same frames through the plain file path
    assert _reconstruct(cap, "--preset", tmp_path / "f.npy.preset.toml", "--out", tmp_path / "again.npy") == 0
    np.testing.assert_array_equal(np.load(tmp_path / "again.npy"), np.load(tmp_path / "f.npy"))


def test_export_refuses_an_incomplete_store(cap, tmp_path, capsys):
    store = tmp_path / "c.zarr"
    assert _reconstruct(cap, *GEOM, "--range", "5:100:10", "--chunk", "4", "--out", store) == 0
    zarr.open_group(str(store), mode="r+")["done"][1] = 0
    assert main(["export", str(store), "--out", str(tmp_path / "f.npy")]) == 1
    err = capsys.readouterr().err
    assert "incomplete (2 of 3 chunks done)" in err and "--resume" in err


def test_monochrome_store_has_one_channel_and_exports_2d_frames(tmp_path):
    path = tmp_path / "mono.dat"
    rng = np.random.default_rng(1)
    write_plain(path, (rng.random((80, 32, 32)) < 0.3).astype(np.uint8))
    geom = ["--width", "32", "--height", "32", "--cfa", "none"]
    assert _reconstruct(path, *geom, "--range", "5:80:10", "--chunk", "3", "--out", tmp_path / "m.zarr") == 0
    assert _frames(tmp_path / "m.zarr").shape == (8, 32, 32, 1)
    assert main(["export", str(tmp_path / "m.zarr"), "--out", str(tmp_path / "m.npy")]) == 0
    assert np.load(tmp_path / "m.npy").shape == (8, 32, 32)


# ---------------------------------------------------------------------------------- the app
def test_app_export_of_a_marked_range_to_zarr_matches_the_cli(cap, tmp_path):
    """The export panel's job (no Qt: spikeview.session.jobs) with a .zarr output writes the CLI's store,
    reports (windows done, total) and returns the store."""
    import threading

    from spikeview.session import jobs
    from spikeview.io import open_source
    from spikeview.recipe import Recipe

    assert _reconstruct(cap, *GEOM, "--range", "5:100:10", "--chunk", "4", "--out", tmp_path / "cli.zarr") == 0
    reports = []

    class Ctx:
        cancelled = threading.Event()
        state: dict = {}

        def report(self, payload):
            reports.append(payload)

    with open_source(cap, width=32, height=32, cfa="RGGB") as src:
        recipe = Recipe().with_values({"run.range": "5:100:10", "stream.width": 32, "stream.height": 32,
                                       "stream.cfa": "RGGB"})
        ticks = jobs.export_ticks(recipe, src.n_frames)
        req = jobs.ExportRequest(src, str(cap), ticks, recipe, None, tmp_path / "app.zarr")
        assert jobs.export_job(req, Ctx()) == [tmp_path / "app.zarr"]
    np.testing.assert_array_equal(_frames(tmp_path / "app.zarr"), _frames(tmp_path / "cli.zarr"))
    assert reports[0] == (0, 10) and reports[-1] == (10, 10)


@pytest.mark.gui
def test_app_export_panel_sends_the_marked_range_to_a_scheduler(cap, tmp_path, qtbot, cluster):
    """Export panel: a scheduler address turns the output into a .zarr store written by the Dask workers,
    with the panel's progress; the store's preset re-runs the same frames through the CLI."""
    pytest.importorskip("PySide6")
    from PySide6 import QtCore

    from spikeview.session import core
    from spikeview.gui.main_window import MainWindow

    _, client = cluster
    w = MainWindow(settings=QtCore.QSettings(str(tmp_path / "s.ini"), QtCore.QSettings.Format.IniFormat))
    qtbot.addWidget(w)
    w.show()
    try:
        w.set_stream(core.open_file(cap, width=32, height=32, cfa="RGGB"))
        s, panel = w.session, w.export_panel
        s.set_mark_in(20)
        s.set_mark_out(79)
        s.set("export_range", "marked")
        panel.cluster.setText(client.scheduler.address)
        out = Path(panel.path.text())
        assert out.suffix == ".zarr" and out.parent == tmp_path and "Zarr store" in panel.count.text()
        ticks = panel.ticks()
        panel.export_btn.click()
        qtbot.waitUntil(lambda: w.notice.kind in ("success", "error") and not w.controller.exporter.is_active(),
                        timeout=120_000)
        assert w.notice.kind == "success", panel.status.text()
        assert panel.progress.value() == len(ticks) == panel.progress.maximum()
        g = zarr.open_group(str(out), mode="r")
        np.testing.assert_array_equal(g["centre_tick"][:], ticks)
        assert _reconstruct(cap, "--preset", f"{out}.preset.toml", "--out", tmp_path / "again.npy") == 0
        np.testing.assert_array_equal(_mapped(out), np.load(tmp_path / "again.npy"))
    finally:
        w.close()
