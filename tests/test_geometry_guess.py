"""Guessing the geometry of plain files without a sidecar, and warnings when the given one looks wrong."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main
from spikeview.errors import GeometryError
from spikeview.io import open_source, write_plain
from spikeview.io.geometry import candidate_sizes, rank_plain_geometries

BAYER_GAINS = {(0, 0): 0.6, (0, 1): 1.0, (1, 0): 1.0, (1, 1): 0.5}  # RGGB, the simulator's spectral gains


def smooth_rates(w: int, h: int, seed: int, cfa: bool) -> np.ndarray:
    """A smooth random scene (Gaussian blobs and a slanted wave) as spikes per tick in [0.05, 0.55]."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(w, h)
    img = np.zeros((h, w))
    for _ in range(6):
        cx, cy, s = rng.uniform(0, 1), rng.uniform(0, 1), rng.uniform(0.05, 0.3)
        img += rng.uniform(0.2, 1) * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * s * s))
    img += 0.3 * np.sin(2 * np.pi * (xx * rng.uniform(1, 4) + yy * rng.uniform(1, 4)))
    rate = 0.05 + 0.5 * (img - img.min()) / (img.max() - img.min())
    if cfa:
        for (py, px), g in BAYER_GAINS.items():
            rate[py::2, px::2] *= g
    return rate


def write_capture(path, w: int, h: int, ticks: int, seed: int = 0, cfa: bool = True, sidecar: bool = False):
    rate = smooth_rates(w, h, seed, cfa).astype(np.float32)
    rng = np.random.default_rng(seed + 1)
    spikes = np.concatenate([rng.random((min(8, ticks - a), h, w), dtype=np.float32) < rate
                             for a in range(0, ticks, 8)])
    return write_plain(path, spikes, cfa="RGGB" if cfa else None, sidecar=sidecar)


SIZES = [(64, 64, 400), (128, 96, 200), (256, 256, 60), (250, 400, 40), (320, 240, 40), (400, 250, 40),
         (160, 120, 100), (1000, 1000, 16)]


@pytest.mark.parametrize("cfa", [True, False], ids=["RGGB", "mono"])
@pytest.mark.parametrize("w, h, ticks", SIZES, ids=[f"{w}x{h}" for w, h, _ in SIZES])
def test_the_true_geometry_ranks_first(tmp_path, w, h, ticks, cfa):
    path = write_capture(tmp_path / "c.dat", w, h, ticks, seed=w + h, cfa=cfa)
    size = path.stat().st_size
    assert (w, h) in candidate_sizes(size)
    guesses = rank_plain_geometries(path)
    assert guesses[0].size == (w, h), [g.describe() for g in guesses]
    assert guesses[0].n_frames == ticks
    assert all(size % (g.width * g.height // 8) == 0 for g in guesses)


def still_image(path, w: int = 400, h: int = 300):
    import OpenImageIO as oiio

    yy, xx = np.mgrid[0:h, 0:w] / h
    img = np.stack([0.5 + 0.4 * np.sin(5 * xx + c) * np.cos(3 * yy - c) for c in range(3)], -1)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, 3, "uint8"))
    out.write_image((img * 255).astype(np.uint8))
    out.close()
    return path


@pytest.mark.parametrize("w, h, ticks, cfa", [(96, 96, 120, "demo"), (250, 400, 40, "none"), (160, 120, 100, "RGGB")])
def test_simulated_captures_rank_first(tmp_path, w, h, ticks, cfa):
    """The project's simulator (realistic noise, nearly periodic integrate-and-fire spikes, a panning scene)."""
    from spikeview.sim import MotionScene, SimConfig, demo_scene, simulate_to_file

    if cfa == "demo":
        scene, cfg = demo_scene(size=w, seed=1), SimConfig(n_ticks=ticks, width=w, height=h, seed=1)
    else:
        scene = MotionScene(still_image(tmp_path / "still.png"), (h, w), pan=(300.0, 100.0))
        cfg = SimConfig(n_ticks=ticks, width=w, height=h, cfa=cfa, seed=1)
    files = simulate_to_file(scene, cfg, tmp_path / "sim.dat")
    files.sidecar.unlink()
    assert rank_plain_geometries(files.dat)[0].size == (w, h)


def test_info_without_a_sidecar_names_the_likely_size_and_lists_it_first(tmp_path, capsys):
    path = write_capture(tmp_path / "c.dat", 256, 256, 60)
    assert main(["info", str(path)]) == 1
    err = capsys.readouterr().err.strip()
    assert "most likely --width 256 --height 256 (60 ticks)" in err and "\n" not in err, err
    with pytest.raises(GeometryError) as e:
        open_source(path)
    assert e.value.candidates[0] == (256, 256)  # what the app's open dialog pre-fills


def test_a_size_that_fits_a_known_sensor_is_not_taken_blindly(tmp_path):
    path = write_capture(tmp_path / "c.dat", 500, 500, 8)  # 250,000 bytes: two 1000x1000 or 20 400x250 frames
    with pytest.raises(GeometryError, match="several known.*its spikes suggest, --width 500 --height 500.*most likely"
                       ) as e:
        open_source(path)
    assert e.value.candidates[0] == (500, 500)
    path = write_capture(tmp_path / "d.dat", 250, 100, 12)  # 37,500 bytes: three 400x250 frames, no other sensor
    with pytest.raises(GeometryError, match="do not look like them.*most likely --width 250 --height 100") as e:
        open_source(path)
    assert e.value.candidates[0] == (250, 100)


def test_random_files_without_a_scene_prefer_square_shapes(tmp_path):
    path = tmp_path / "r.dat"
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 64 * 64 // 8 * 3, dtype=np.uint8).tobytes())
    sizes = [g.size for g in rank_plain_geometries(path)]
    assert (64, 64) in sizes and sizes[0][0] == sizes[0][1]


# ------------------------------------------------------------------------------ warnings
def test_right_settings_give_no_warning(tmp_path):
    path = write_capture(tmp_path / "c.dat", 128, 96, 200)
    with open_source(path, width=128, height=96, cfa="RGGB") as src:
        assert src.info.warnings == []


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_a_wrong_width_is_refused_before_anything_is_written(tmp_path, capsys, cfa):
    path = write_capture(tmp_path / "c.dat", 128, 96, 200, cfa=cfa != "none")
    with open_source(path, width=96, height=128, cfa=cfa) as src:
        assert any("rows do not line up at width 96" in w and "128x96" in w for w in src.info.warnings), src.info.warnings
        assert src.info.likely_size == (128, 96)
    with open_source(path, width=128, height=96, cfa=cfa) as src:
        assert src.info.likely_size is None
    out = tmp_path / "f.png"
    assert main(["reconstruct", str(path), "--width", "192", "--height", "64", "--cfa", cfa, "--at", "100",
                 "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "c.dat: the rows do not line up at 192x64" in err and "--width 128 --height 96" in err, err
    assert "--keep-geometry" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists() and not list(tmp_path.glob("f*"))
    # the size it names reads the file; --keep-geometry writes it as given, with the warning
    assert main(["reconstruct", str(path), "--width", "128", "--height", "96", "--cfa", cfa, "--at", "100",
                 "--out", str(out)]) == 0
    assert "rows do not line up" not in capsys.readouterr().err
    assert main(["reconstruct", str(path), "--width", "192", "--height", "64", "--cfa", cfa, "--at", "100",
                 "--out", str(tmp_path / "g.png"), "--keep-geometry"]) == 0
    err = capsys.readouterr().err
    assert "spikeview: warning: c.dat: the rows do not line up at width 192" in err and "frames are 128x96" in err
    assert (tmp_path / "g.png").exists()


def test_an_odd_width_with_a_colour_filter_is_reported(tmp_path):
    path = write_capture(tmp_path / "c.dat", 120, 64, 16)  # 960 bytes per frame
    with open_source(path, width=15 * 8, height=64, cfa="RGGB") as src:
        assert not any("odd width" in w for w in src.info.warnings)
    with open_source(path, width=15, height=512, cfa="RGGB") as src:  # 7680 pixels: whole bytes, odd width
        assert any("odd width (15)" in w and "--cfa none" in w for w in src.info.warnings), src.info.warnings


def test_a_wrong_colour_filter_phase_is_reported(tmp_path, capsys):
    path = write_capture(tmp_path / "c.dat", 128, 96, 200)  # written as RGGB
    with open_source(path, width=128, height=96, cfa="GRBG") as src:
        assert any("green sites of the GRBG filter fire at different rates" in w and "--cfa RGGB" in w
                   for w in src.info.warnings), src.info.warnings
    assert main(["info", str(path), "--width", "128", "--height", "96", "--cfa", "GBRG"]) == 0
    assert "warning:     the two green sites of the GBRG filter" in capsys.readouterr().out


@pytest.mark.parametrize("seed", range(6))
def test_random_captures_with_given_settings_get_no_false_warning(tmp_path, seed):
    rng = np.random.default_rng(seed)
    h, w = (8, 8) if seed % 2 else (16, 24)
    spikes = rng.random((int(rng.integers(2, 60)), h, w)) < rng.uniform(0.05, 0.9)
    path = write_plain(tmp_path / "r.dat", spikes, sidecar=False)
    with open_source(path, width=w, height=h, cfa="RGGB") as src:
        assert src.info.warnings == [], src.info.warnings


def test_a_size_that_fits_both_sensors_names_the_one_the_spikes_match(tmp_path):
    path = write_capture(tmp_path / "c.dat", 400, 250, 40)  # 500,000 bytes: also four 1000x1000 frames
    with pytest.raises(GeometryError, match="--width 400 --height 250; --format plain --width 1000.*point to the "
                                            "first, 400x250 with 40 ticks") as e:
        open_source(path)
    assert e.value.candidates == [(400, 250), (1000, 1000)]


# ------------------------------------------------------------------ flat scenes, few ticks (issue 14)
def _flat_capture(tmp_path, w: int, h: int, ticks: int, cfa: str, seed: int = 7):
    """A uniform grey through the simulator: only the pixels themselves (fixed pattern, integrate-and-fire) tell
    the frame size."""
    from spikeview.sim import MotionScene, SimConfig, simulate_to_file

    scene = MotionScene(np.full((h, w, 3), 0.7, dtype=np.float32), (h, w))
    files = simulate_to_file(scene, SimConfig(n_ticks=ticks, width=w, height=h, cfa=cfa, seed=seed),
                             tmp_path / "flat.dat")
    files.sidecar.unlink()
    return files.dat


def test_integrate_and_fire_pixels_mark_the_frame_size_from_tick_to_tick(tmp_path):
    from spikeview.io.geometry import TICK_EVIDENCE, tick_correlation, tick_frame_size

    buf = np.fromfile(_flat_capture(tmp_path, 64, 64, 50, "none"), dtype=np.uint8)
    fb = 64 * 64 // 8
    assert tick_correlation(buf, fb) < -0.3  # one pixel on consecutive ticks rarely fires twice
    for other in (fb // 2, fb + 8, 3 * fb // 4):  # different pixels: independent phases
        assert abs(tick_correlation(buf, other)) < TICK_EVIDENCE / 2, other
    assert tick_frame_size(buf, [8, fb // 2, fb, 2 * fb])[0] == fb
    # Bernoulli spikes carry no such signature: no frame size is claimed
    bern = np.fromfile(write_capture(tmp_path / "b.dat", 64, 64, 50, cfa=False), dtype=np.uint8)
    assert tick_correlation(bern, fb) > -TICK_EVIDENCE / 2  # (slightly positive: a pixel keeps its rate)
    assert tick_frame_size(bern, [8, fb // 2, fb, 2 * fb])[0] is None


@pytest.mark.parametrize("w, h, ticks, cfa", [(128, 128, 50, "none"), (64, 64, 100, "RGGB"), (256, 128, 50, "RGGB")])
def test_flat_grey_captures_with_few_ticks_rank_first(tmp_path, w, h, ticks, cfa):
    """A uniform grey: the frame size from tick to tick, the width from the colour filter's 2x2 pattern (RGGB)
    or, monochrome, from the shape prior alone (a flat monochrome scene has no rows to line up)."""
    guesses = rank_plain_geometries(_flat_capture(tmp_path, w, h, ticks, cfa))
    assert guesses[0].size == (w, h), [g.describe() for g in guesses]


@pytest.mark.parametrize("cfa", [True, False], ids=["RGGB", "mono"])
def test_a_known_sensor_file_cut_short_is_still_guessed_at_its_size(tmp_path, capsys, cfa):
    """A copy cut short (a partial last tick) no longer divides by 400x250: the guess must not fall to a row-sized frame."""
    full = write_capture(tmp_path / "full.dat", 400, 250, 40, seed=3, cfa=cfa)
    cut = tmp_path / "cut.dat"
    cut.write_bytes(full.read_bytes()[:-100])
    best = rank_plain_geometries(cut)[0]
    assert (best.size, best.n_frames, best.trailing) == ((400, 250), 39, 12400), best
    assert any("partial last tick" in r for r in best.reasons)
    assert main(["info", str(cut)]) == 1
    assert "most likely --width 400 --height 250 (39 ticks)" in capsys.readouterr().err
    with open_source(cut, width=400, height=250, cfa="RGGB" if cfa else "none") as src:
        assert src.n_frames == 39


def test_a_monochrome_capture_read_with_a_colour_filter_is_reported(tmp_path, capsys):
    path = write_capture(tmp_path / "m.dat", 128, 96, 400, cfa=False)  # a monochrome sensor
    with open_source(path, width=128, height=96, cfa="RGGB") as src:
        assert any("four 2x2 sites fire alike" in w and "--cfa none" in w for w in src.info.warnings), src.info.warnings
    with open_source(path, width=128, height=96, cfa=None) as src:
        assert src.info.warnings == [], src.info.warnings
    bayer = write_capture(tmp_path / "c.dat", 128, 96, 400)  # a colour filter's sites: no such warning
    with open_source(bayer, width=128, height=96, cfa="RGGB") as src:
        assert not any("alike" in w for w in src.info.warnings), src.info.warnings
    assert main(["info", str(path), "--width", "128", "--height", "96", "--cfa", "BGGR"]) == 0
    assert "read with a colour filter (--cfa BGGR), but its four 2x2 sites fire alike" in capsys.readouterr().out


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_a_dim_noise_free_pan_along_the_rows_is_not_refused_as_sheared(tmp_path, cfa):
    """A noise-free integrate-and-fire capture (as the ecosystem's simulators make) of a textured scene at 0.06 spikes
    per tick panning a photosite a window along its rows, 256x256, no sidecar: its mean rates are smeared along the
    rows, so they alone "lined up" better at 512x128, and the CLI refused to reconstruct the file at its true size.
    The whole file's spikes line up best at 256x256 (rank_plain_geometries), and that decides: no warning, no refusal."""
    import skimage.data
    from skimage.transform import resize

    n, ticks = 256, 400
    img = skimage.data.chelsea()[..., :3].astype(np.float64) / 255.0
    big = resize(img, (n, n + 48), anti_aliasing=True)
    lum = big.mean(-1)
    mos = lum.copy()
    if cfa is not None:
        mos[0::2, 0::2], mos[0::2, 1::2] = big[0::2, 0::2, 0], big[0::2, 1::2, 1]
        mos[1::2, 0::2], mos[1::2, 1::2] = big[1::2, 0::2, 1], big[1::2, 1::2, 2]
    acc = np.random.default_rng(1).random((n, n))
    spikes = np.empty((ticks, n, n), np.uint8)
    for t in range(ticks):
        s = 2 * (t // 20) if cfa is not None else t // 10  # whole photosites (Bayer: cells), a photosite a window
        acc += 0.06 * mos[:, s:s + n]
        spikes[t] = acc >= 1.0
        acc[spikes[t] == 1] -= 1.0
    path = write_plain(tmp_path / "pan.dat", spikes, cfa=cfa, sidecar=False)
    src = open_source(path, width=n, height=n, cfa=cfa or "none")
    assert src.info.likely_size is None and not any("line up" in w for w in src.info.warnings), src.info.warnings
    out = tmp_path / "f.npy"
    assert main(["reconstruct", str(path), "--width", str(n), "--height", str(n), "--cfa", cfa or "none",
                 "--method", "tfp", "--at", "200", "--out", str(out)]) == 0
    assert out.exists()
