"""Low light and real captures (issue 25): the scores a blur cannot win, and the guided default on a real dark
capture (tests/data/uhsr.npz, a real sensor's static scene) and simulated dark static scenes, mono and RGGB."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from spikeview.metrics import detail_kept, patchiness

REAL = Path(__file__).parent / "data" / "uhsr.npz"


def _scene(size: int = 96) -> np.ndarray:
    import skimage.data

    return skimage.data.camera()[100:100 + size, 180:180 + size].astype(np.float64) / 255.0


def test_detail_ranks_the_truth_first_and_punishes_blur_and_noise():
    truth = _scene()
    rng = np.random.default_rng(0)
    blur = gaussian_filter(truth, 2.0)
    noisy = truth + rng.normal(0, 0.3, truth.shape)
    assert detail_kept(truth, truth) == pytest.approx(1.0)
    assert detail_kept(blur, truth) < 0.6 and detail_kept(noisy, truth) < 0.6
    assert detail_kept(0.3 * truth, truth) == pytest.approx(1.0)  # the exposure does not count (one global gain)
    # a blur that PSNR prefers to the noisy frame still loses detail to a mildly noisy one
    mild = truth + rng.normal(0, 0.03, truth.shape)
    assert detail_kept(mild, truth) > detail_kept(blur, truth)
    rgb = np.repeat(truth[..., None], 3, axis=-1)
    assert detail_kept(rgb, truth) == pytest.approx(1.0)  # colour frames: their luminance


def test_patchiness_finds_a_patch_of_raw_noise_in_an_even_frame():
    rng = np.random.default_rng(1)
    flat = np.full((128, 128), 0.5)
    even = flat + rng.normal(0, 0.02, flat.shape)
    patchy = even.copy()
    patchy[32:64, 32:80] += rng.normal(0, 0.2, (32, 48))  # 6 of 64 tiles: raw noise left in a smooth frame
    assert patchiness(even, flat) < 1.6
    assert patchiness(patchy, flat) > 3.0
    # against the truth, a textured scene reconstructed cleanly is even: its texture cancels in the error
    truth = 0.2 + 0.6 * _scene(128)
    clean = truth + rng.normal(0, 0.01, truth.shape)
    assert patchiness(clean, truth, truth=True) < 1.6
    blotchy = clean.copy()
    blotchy[:48, :64] += rng.normal(0, 0.08, (48, 64))
    assert patchiness(blotchy, truth, truth=True) > 3.0


@pytest.mark.skipif(not REAL.exists(), reason="tests/data/uhsr.npz is missing")
def test_bench_real_scores_the_guided_default_on_a_real_dark_capture(capsys):
    """`spikeview bench --real`: the guided default keeps at least TFI's detail (−0.02) against the capture's
    independent long exposure, is evenly denoised (patchiness ≤ 2) and less noisy than the 10-tick TFP."""
    from spikeview.bench.lowlight import run_real

    rows = {r["method"]: r for r in run_real([str(REAL)])}
    g, tfi, tfp = rows["guided"], rows["tfi"], rows["tfp"]
    assert g["detail"] >= tfi["detail"] - 0.02, (g, tfi)
    assert g["patchiness"] <= 2.0, g
    assert g["noise"] < 0.2 * tfp["noise"], (g, tfp)


@pytest.mark.skipif(not REAL.exists(), reason="tests/data/uhsr.npz is missing")
def test_the_real_dark_capture_pools_its_static_scene_and_the_plan_says_why():
    """The real capture's photosites pool every neighbour of ±3 windows (its darkest tiles once kept their own window:
    16×16 blocks of raw noise) on ≥ 90 % of them; its scene drifts (5 photosites down over the 200 ticks, measured
    on the whole frame), so the low-light support stops at ±3 windows instead of smearing the rotor blades over ±9;
    and diffusion runs: its noise, small in absolute units, is judged against the frame's white."""
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.observation import Observation
    from spikeview.guided.plan import make_plan
    from spikeview.io import open_source

    src = open_source(str(REAL))
    obs = Observation.from_source(src, 100, 10, eta=2.0, radius=3)
    nb = obs.dtau / 10 - 1
    assert (nb >= 6).mean() >= 0.90
    assert obs.pooling.kind == "static" and not obs.pooling.extended
    vy, vx = obs.pooling.drift
    assert vy == pytest.approx(0.36, abs=0.06) and abs(vx) < 0.06  # 5 photosites over 140 ticks, downwards
    assert "drifts 0.3" in obs.pooling.reason and "stops at ±3 windows" in obs.pooling.reason
    plan = make_plan(obs, GuidedConfig())
    assert plan.diffusion and plan.exposure > 4, plan.reasons["diffusion"]
    assert "relative to the frame's white" in plan.reasons["diffusion"]


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_simulated_low_light_guided_beats_tfi_and_keeps_its_detail(tmp_path, cfa):
    """A static scene at 0.03 spikes per tick (0.3 a window), through the CLI's defaults: the guided frame is ≥ 2 dB
    above TFI with the SpikeCV search (±32 ticks; one global gain) and keeps at least its detail (−0.02). The CLI's TFI
    now searches as far as a dark capture needs (spikeview.pipeline.tfi_reach): on Bayer the guided frame is still ≥ 2 dB
    above it; in monochrome that TFI can be the better frame (the guided frame's Q floor, which takes the simulator's
    dark rate off, also takes the darkest half of this scene to 0), a known shortfall said in results/lowlight.md, held
    here to no worse than 2 dB below it."""
    from PIL import Image

    from spikeview.bench.lowlight import _reconstruct
    from spikeview.cli.main import main
    from spikeview.metrics import colour_scores

    Image.fromarray((_scene(128) * 255).astype(np.uint8)).save(tmp_path / "s.png")
    cap = tmp_path / "c.dat"
    assert main(["simulate", str(tmp_path / "s.png"), "--ticks", "360", "--cfa", cfa, "--rate", "0.03",
                 "--width", "128", "--height", "128", "--out", str(cap)]) == 0
    g = np.load(tmp_path / "c.gt.npz")
    i = int(np.argmin(np.abs(g["ticks"] - 180)))
    truth = g["frames"][i].astype(np.float64)
    truth = truth.mean(axis=-1) if cfa == "none" else truth
    truth = truth / truth.max()
    out = {m: _reconstruct(str(cap), m, 180, tmp_path) for m in ("tfi", "guided")}
    # TFI with the ±32-tick search, as the pipeline makes its frames (one global gain: the white point does not count)
    from spikeview.classical.reconstruct import reconstruct_frames
    from spikeview.io import open_source
    from spikeview.pipeline import prepare_sequence
    from spikeview.recipe import Recipe

    with open_source(cap) as src:
        recipe = Recipe().with_values({"run.method": "tfi"})
        state = prepare_sequence(src, recipe, warn=False)
        assert state.tfi_reach is not None and state.tfi_reach > 32
        cfg = recipe.classical.replace(method="tfi", tfi_half_window=32)
        out["tfi32"] = np.squeeze(next(reconstruct_frames(src, [180], cfg, alpha=state.alpha))).astype(np.float64)
    ps = {m: colour_scores(x, truth)["psnr_1gain"] for m, x in out.items()}
    det = {m: detail_kept(x, truth) for m, x in out.items()}
    assert ps["guided"] >= ps["tfi32"] + 2.0, ps
    assert det["guided"] >= det["tfi32"] - 0.02, det
    assert ps["tfi"] >= ps["tfi32"] + 2.0, ps  # the reach: the darker half no longer sits on the capped level
    assert ps["guided"] >= ps["tfi"] + (2.0 if cfa == "RGGB" else -2.0), ps


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_the_plan_says_how_to_keep_the_shadows_of_a_noise_free_dark_capture(cfa):
    """A noise-free integrate-and-fire capture (an ecosystem-style simulation) at 0.06 spikes per tick whose darkest
    patch holds light: its darkest floor is read as a dark rate, and Q's per-window grid takes it off, though nearly every
    rate comes from spike intervals (an ecosystem-style dark chelsea: 25.45 dB with Q, 33.24 without). No rule here
    can tell that floor from a dark current in monochrome (spikeview's simulator and the real capture need Q there), so
    the plan's quantise row says it and names --no-quantise; a colour capture without a cast (made from RGB frames, as
    this one) has its floor read as light (spikeview.classical.defects.darkest_floor)."""
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.observation import Observation
    from spikeview.guided.plan import make_plan
    from spikeview.io import ArraySource

    n = 96
    light = 0.25 + 0.75 * _scene(n)
    acc = np.random.default_rng(2).random((n, n))
    spikes = np.empty((400, n, n), np.uint8)
    for t in range(400):
        acc += 0.06 * light
        spikes[t] = acc >= 1.0
        acc[spikes[t] == 1] -= 1.0
    obs = Observation.from_source(ArraySource(spikes, cfa=cfa), 200, 10, eta=2.0, radius=3)
    plan = make_plan(obs, GuidedConfig())
    assert obs.pooling.interval_share >= 0.5, obs.pooling.reason
    if cfa is None:  # a monochrome capture cannot tell: the plan says it
        assert plan.quantise and "--no-quantise" in plan.reasons["quantise"], plan.reasons["quantise"]
    else:  # a colour one without a cast was made from RGB frames, without a dark current: no floor taken off
        assert obs.floor == 0.0 and obs.quantise_window() > obs.window, (obs.floor, plan.reasons["quantise"])
        assert "--no-quantise" not in plan.reasons["quantise"]
