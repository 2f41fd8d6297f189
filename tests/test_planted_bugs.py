"""One-line bugs that once passed the whole suite when planted alone (issue 29): each test here fails with its bug.

* ``bf16_speedup`` returning its inverse (bfloat16 time over float32 time): auto would spend bfloat16 where
  it is slower;
* ``check_store`` accepting a monochrome store that records a colour cast α;
* per-site gains written transposed (``gains[px, py]``): R and B swapped for GRBG/GBRG white points;
* the keyframe restart disabled (a range's reuse / warm-start chains never restart).
"""

from __future__ import annotations

import numpy as np
import pytest



def test_the_bfloat16_speedup_is_float32_time_over_bfloat16_time():
    from spikeview.guided.precision import BF16_MIN_SPEEDUP, _auto, speedup_of

    assert speedup_of(2.0, 1.0) == 2.0 and speedup_of(1.0, 2.0) == 0.5
    base = {"avx512_bf16": True, "onednn_bf16": True, "avx512f": True, "avx2": True, "onednn_max_isa": "ALL"}
    fast = speedup_of(float32_seconds=1.53, bf16_seconds=0.80)  # an EPYC-like CPU: bf16 pays
    slow = speedup_of(float32_seconds=1.53, bf16_seconds=2.58)  # the Xeon without AMX: bf16 is slower
    assert fast >= BF16_MIN_SPEEDUP > slow
    assert _auto({**base, "bf16_speedup": fast})[0] == "bfloat16-mixed"
    assert _auto({**base, "bf16_speedup": slow})[0] == "float32"


@pytest.mark.parametrize("cfa", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_the_white_point_puts_each_gain_on_its_own_sites(cfa):
    """R sites always fire, G half the time, B a quarter: with α = (1, 2, 4) every corrected rate is 1/η, so the
    white point is 1/η; R and B gains on each other's sites would make it 4/η."""
    from spikeview.classical.colour_cast import estimate_white
    from spikeview.io.source import ArraySource

    t, h, w = 40, 16, 16
    rate = {"R": 1.0, "G": 0.5, "B": 0.25}
    ticks = np.arange(t)[:, None, None]
    spikes = np.zeros((t, h, w), np.uint8)
    for (py, px), ch in zip(((0, 0), (0, 1), (1, 0), (1, 1)), cfa):
        period = round(1 / rate[ch])
        spikes[:, py::2, px::2] = ((ticks % period) == 0)
    src = ArraySource(spikes, cfa=cfa)
    white = estimate_white(src, np.array([1.0, 2.0, 4.0]), window=8, eta=2.0)
    assert 0.4 < white < 0.8  # 1/η, up to the levels' half-step spread (swapped gains: about 4/η = 2)


def test_a_monochrome_store_that_records_a_colour_cast_is_refused(tmp_path):
    pytest.importorskip("distributed")
    zarr = pytest.importorskip("zarr")
    from spikeview.cli.main import main
    from spikeview.cluster.store import check_store
    from spikeview.errors import SpikeviewError
    from spikeview.io.plain import write_plain

    rng = np.random.default_rng(2)
    cap = tmp_path / "c.dat"
    write_plain(cap, (rng.random((48, 16, 16)) < 0.4).astype(np.uint8))
    store = tmp_path / "s.zarr"
    assert main(["reconstruct", str(cap), "--width", "16", "--height", "16", "--cfa", "none", "--window", "4",
                 "--range", "2:42:4", "--out", str(store)]) == 0
    check_store(store)  # as written: accepted
    g = zarr.open_group(str(store), mode="r+")
    attrs = dict(g.attrs["spikeview"])
    attrs["alpha"] = [1.0, 1.0, 1.0]
    g.attrs["spikeview"] = attrs
    with pytest.raises(SpikeviewError, match="a monochrome store records a colour cast alpha"):
        check_store(store)


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_a_long_range_restarts_its_chains_at_every_keyframe(cfa):
    """Windows from a keyframe on are what a run starting at that keyframe gives (reuse restarts there): without
    the restart, a static scene's windows after the keyframe would be the reused result of the windows before it."""
    from spikeview.pipeline import KEYFRAME, reconstruct_windows
    from spikeview.recipe import Recipe
    from spikeview.sim import SimConfig, StaticScene, simulate

    img = np.random.default_rng(0).random((24, 24, 3)).astype(np.float32) * 0.6 + 0.2
    src = simulate(StaticScene(img, srgb=False), SimConfig(n_ticks=10 * (KEYFRAME + 4) + 10, width=24, height=24,
                                                              cfa=cfa, seed=1))
    recipe = Recipe().with_values({"run.method": "guided", "guided.steps": 1, "guided.temporal_radius": 0,
                                   "guided.precision": "float32", "classical.alpha": None})
    centres = [5 + 10 * i for i in range(KEYFRAME + 3)]
    infos: list = []
    whole = list(reconstruct_windows(src, centres, recipe, infos=infos))
    assert any(i.mode == "reused" for i in infos[1:KEYFRAME])  # the scene is static: windows are reused
    tail = list(reconstruct_windows(src, centres[KEYFRAME:], recipe))
    for a, b in zip(whole[KEYFRAME:], tail, strict=True):
        assert np.array_equal(a, b)
    assert infos[KEYFRAME].mode != "reused"
