"""Simulation settings as data, and simulating to .dat + sidecar + ground truth."""

import numpy as np
import pytest

from spikeview.config import load_toml
from spikeview.errors import Cancelled, InputFileError, OutputFileError, ParameterError
from spikeview.io import open_source
from spikeview.sim.config import SimConfig
from spikeview.sim.scenes import ArrayScene, StaticScene
from spikeview.sim.simulator import simulate
from spikeview.sim.write import ground_truth_path, load_ground_truth, simulate_to_file


def _scene(seed=0, n=5, h=16, w=24, fps=200.0):
    frames = np.random.default_rng(seed).uniform(0, 1, (n, h, w, 3)).astype(np.float32)
    return ArrayScene(frames, fps=fps)  # 5 frames at 200 fps = 25 ms = 500 ticks


# ------------------------------------------------------------------------------- settings
def test_sim_config_saves_and_loads_unchanged(tmp_path):
    cfg = SimConfig(width=64, height=48, crop=[1, 2, 30, 40], n_ticks=123, cfa="bggr", spectral_gains=(0.5, 1, 0.4),
                    shot_noise=False, seed=42, gt_every=5, flip_vertical=False, jitter_std_v=0.01)
    assert cfg.cfa == "BGGR"
    path = cfg.save(tmp_path / "sim.toml")
    assert SimConfig.load(path) == cfg
    assert SimConfig.load(SimConfig().save(tmp_path / "default.toml")) == SimConfig()


@pytest.mark.parametrize("bad, match", [
    ({"rate": 0.0}, "rate"),
    ({"n_ticks": 0}, "n_ticks"),
    ({"cfa": "RGBG"}, "Unknown CFA"),
    ({"spectral_gains": (1.0, -1.0, 1.0)}, "spectral_gains"),
    ({"gt_every": 0}, "gt_every"),
    ({"crop": [0, 0, 10]}, "crop"),
    ({"reset_factor": 1.5}, "reset_factor"),
    ({"tick_rate": float("nan")}, "tick_rate"),
])
def test_sim_config_rejects_bad_values(bad, match):
    with pytest.raises(ParameterError, match=match):
        SimConfig(**bad)


def test_sim_config_rejects_unknown_keys_in_files(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("rate = 0.6\nshotnoise = true\n")
    with pytest.raises(ParameterError, match="shotnoise"):
        SimConfig.load(path)


def test_derived_constants_of_the_default_sensor():
    cfg = SimConfig()
    # 4.348 fF · 1 V / 1.602e-19 C = 27,139 electrons per threshold
    assert cfg.electrons_per_threshold == pytest.approx(27139, rel=1e-4)
    # 0.4442 pA · 50 µs / q = 138.6 electrons per tick
    assert cfg.dark_threshold_per_tick * cfg.electrons_per_threshold == pytest.approx(138.6, rel=1e-3)


# ------------------------------------------------------------------------------- files
@pytest.mark.parametrize("flip", [True, False])
def test_simulate_to_file_matches_the_in_memory_capture(tmp_path, flip):
    cfg = SimConfig(n_ticks=500, gt_every=37, seed=3, flip_vertical=flip)
    calls = []
    files = simulate_to_file(_scene(), cfg, tmp_path / "c.dat", progress=lambda a, b: calls.append((a, b)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.dat", "c.dat.toml", "c.gt.npz"]
    assert calls[-1] == (500, 500)
    cap = simulate(_scene(), cfg)
    expected = cap.read(0, 500)
    # the raw bytes: 16·24/8 = 48 bytes per tick, LSB first, rows upside down when flipped
    raw = np.fromfile(files.dat, np.uint8)
    assert raw.size == 500 * 48
    bits = np.unpackbits(raw.reshape(500, 48), axis=1, bitorder="little").reshape(500, 16, 24)
    assert np.array_equal(bits[:, ::-1] if flip else bits, expected)
    # read back through spikeview.io with the sidecar: same spikes, CFA and settings
    with open_source(files.dat) as src:
        assert (src.width, src.height, src.n_frames, src.cfa) == (24, 16, 500, "RGGB")
        assert src.info.flip_vertical is flip
        assert np.array_equal(src.read(0, 500), expected)
        assert SimConfig.from_dict(src.info.extra["simulation"]) == cfg
    side = load_toml(files.sidecar)
    assert side["ground_truth"]["file"] == "c.gt.npz"
    assert side["scene"]["kind"] == "ArrayScene"
    assert SimConfig.load(files.sidecar, table="simulation") == cfg
    # ground truth: every 37 ticks from 0, equal to the scene at those ticks, never flipped
    gt = load_ground_truth(files.dat)
    assert np.array_equal(gt.ticks, np.arange(0, 500, 37))
    assert gt.frames.shape == (14, 16, 24, 3) and gt.frames.dtype == np.float32
    for t in (0, 37, 481):
        # stored as float16: round to nearest keeps the value within 2**-11 relative (IEEE 754 half)
        np.testing.assert_allclose(gt.at(t), cap.gt_at(t), rtol=2.0**-11, atol=2.0**-25)
        assert not np.array_equal(gt.at(t), gt.at(t).astype(np.float16).astype(np.float32) + 2.0**-10)
    assert gt.tick_rate == 20000.0
    with pytest.raises(ParameterError, match="ticks \\[37, 74\\]"):
        gt.at(40)
    assert gt.nearest(40)[0] == 37


def test_ground_truth_of_a_static_scene_and_gt_path(tmp_path):
    img = np.full((8, 8, 3), 0.25, np.float32)
    files = simulate_to_file(StaticScene(img), SimConfig(n_ticks=20, gt_every=10), tmp_path / "s.dat")
    assert files.ground_truth == ground_truth_path(tmp_path / "s.dat") == tmp_path / "s.gt.npz"
    gt = load_ground_truth(files.ground_truth)
    assert gt.frames.shape == (2, 8, 8, 3)
    assert np.all(gt.frames == 0.25)


def test_simulate_to_file_errors_leave_no_files(tmp_path):
    with pytest.raises(OutputFileError, match="does not exist"):
        simulate_to_file(_scene(), SimConfig(n_ticks=10), tmp_path / "missing" / "c.dat")
    with pytest.raises(ParameterError, match="multiple of 8"):
        simulate_to_file(StaticScene(np.zeros((3, 5, 3), np.float32)), SimConfig(n_ticks=10), tmp_path / "odd.dat")
    with pytest.raises(Cancelled):
        simulate_to_file(_scene(), SimConfig(n_ticks=100), tmp_path / "c.dat", cancel=lambda: True)
    assert list(tmp_path.iterdir()) == []
    simulate_to_file(_scene(), SimConfig(n_ticks=10), tmp_path / "c.dat")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(OutputFileError, match="already exists.*--overwrite"):
        simulate_to_file(_scene(), SimConfig(n_ticks=10, seed=1), tmp_path / "c.dat")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    simulate_to_file(_scene(), SimConfig(n_ticks=10, seed=1), tmp_path / "c.dat", overwrite=True)
    assert (tmp_path / "c.dat").read_bytes() != before["c.dat"]


def test_simulate_never_overwrites_its_input_even_with_overwrite(tmp_path):
    still = tmp_path / "still.gt.npz"  # an input named like the ground truth of the output
    still.write_bytes(b"precious")
    with pytest.raises(OutputFileError, match="input of the run"):
        simulate_to_file(_scene(), SimConfig(n_ticks=10), tmp_path / "still.dat", overwrite=True, inputs=[still])
    assert still.read_bytes() == b"precious" and not (tmp_path / "still.dat").exists()


def test_ground_truth_is_compressed_half_precision_and_no_larger_than_the_capture_by_default(tmp_path):
    files = simulate_to_file(_scene(h=32, w=32), SimConfig(n_ticks=500, seed=2), tmp_path / "c.dat")
    assert SimConfig().gt_every == 50
    with np.load(files.ground_truth) as z:
        assert z["frames"].dtype == np.float16 and z["frames"].shape == (10, 32, 32, 3)
    import zipfile

    with zipfile.ZipFile(files.ground_truth) as zf:
        assert zf.getinfo("frames.npy").compress_type == zipfile.ZIP_DEFLATED
    assert files.ground_truth.stat().st_size <= files.dat.stat().st_size


def test_load_ground_truth_errors(tmp_path):
    with pytest.raises(InputFileError, match="not found"):
        load_ground_truth(tmp_path / "none.dat")
    np.savez(tmp_path / "x.gt.npz", spikes=np.zeros(3))
    with pytest.raises(InputFileError, match="frames"):
        load_ground_truth(tmp_path / "x.gt.npz")
    (tmp_path / "y.gt.npz").write_bytes(b"junk")
    with pytest.raises(InputFileError, match="not a readable"):
        load_ground_truth(tmp_path / "y.gt.npz")
