"""The white point's two rules beyond the plain percentile: a file without a sidecar near the ecosystem's conversion
rate takes it (its synthetic data sets fire 0.6 spikes per tick at white; spikeview's own captures, and files whose
estimate lies far from it, keep the estimate: :func:`spikeview.classical.colour_cast.ecosystem_white`), and a dark
capture's white is measured over windows long enough to hold a few spikes at the white
(:func:`spikeview.classical.colour_cast.estimate_white`), mono and Bayer."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.classical.colour_cast import ECOSYSTEM_RATE, ecosystem_white
from spikeview.cli.main import main
from spikeview.io.plain import write_plain


def _integrate_and_fire(rate: np.ndarray, ticks: int, seed: int = 3) -> np.ndarray:
    """Regularly firing photosites (the ecosystem's simulators): one spike each time ``rate`` per tick sums past 1."""
    v = np.random.default_rng(seed).random(rate.shape)
    out = np.zeros((ticks,) + rate.shape, np.uint8)
    for t in range(ticks):
        v += rate
        fire = v >= 1.0
        out[t] = fire
        v[fire] -= 1.0
    return out


def _capture(tmp_path, peak: float, sidecar: bool, cfa: str | None = None):
    """64×96, a left-to-right ramp of intensity up to 1 (the last columns white), firing ``peak·I`` per tick."""
    ramp = np.linspace(0.05, 1.0, 96)
    ramp = np.minimum(ramp / 0.97, 1.0)  # a few columns at full white, as a frame with highlights has
    intensity = np.broadcast_to(ramp[None, :], (64, 96))
    path = tmp_path / f"cap_{peak:g}_{int(sidecar)}_{cfa}.dat"
    write_plain(path, _integrate_and_fire(peak * intensity, 300), sidecar=sidecar, cfa=cfa)
    return path, intensity


def _run(path, tmp_path, capsys, *extra: str):
    out = tmp_path / (path.stem + ".npy")
    geom = [] if (path.parent / (path.name + ".toml")).exists() else ["--width", "96", "--height", "64"]
    assert main(["reconstruct", str(path), *geom, "--method", "tfp", "--window", "30", "--at", "150",
                 "--transfer", "linear", "--out", str(out), "--overwrite", *extra]) == 0
    return np.squeeze(np.load(out)).astype(np.float64), capsys.readouterr().err


def test_mono_file_without_sidecar_takes_the_ecosystem_conversion_rate(tmp_path, capsys):
    path, intensity = _capture(tmp_path, ECOSYSTEM_RATE, sidecar=False)
    x, err = _run(path, tmp_path, capsys, "--cfa", "none")
    assert "white point 0.6 " in err and "Spike-Zoo" in err
    # the frame is rate / 0.6: the intensity it was made from (30-tick windows: a step of 1/18 at most)
    assert abs(float(x.mean()) - float(intensity.mean())) < 0.01
    assert np.abs(x - intensity)[:, 2:-2].mean() < 0.03


@pytest.mark.parametrize("peak", [0.3, 0.9])
def test_a_file_far_from_the_conversion_rate_keeps_its_estimate(tmp_path, capsys, peak):
    path, _ = _capture(tmp_path, peak, sidecar=False)
    x, err = _run(path, tmp_path, capsys, "--cfa", "none")
    assert "99.9th percentile of the sequence's rates" in err and "Spike-Zoo" not in err
    assert 0.9 < float(np.quantile(x, 0.999)) <= 1.0 + 1e-6  # its own white maps to full scale


def test_spikeviews_own_capture_keeps_its_estimate(tmp_path, capsys):
    """A sidecar says the file is not one of the ecosystem's: the estimate stays, even at 0.6 spikes per tick."""
    path, _ = _capture(tmp_path, ECOSYSTEM_RATE, sidecar=True)
    _, err = _run(path, tmp_path, capsys)
    assert "Spike-Zoo" not in err and "99.9th percentile of the sequence's rates" in err


def test_bayer_without_sidecar(tmp_path, capsys):
    """A Bayer file's frames carry the colour gains (Y·α/η), not plain rates: the estimate stays; with the colour cast
    off its frames are plain rates again, and the conversion rate applies as for a monochrome file."""
    path, intensity = _capture(tmp_path, ECOSYSTEM_RATE, sidecar=False, cfa="RGGB")
    _, err = _run(path, tmp_path, capsys, "--cfa", "RGGB")
    assert "Spike-Zoo" not in err
    x, err = _run(path, tmp_path, capsys, "--cfa", "RGGB", "--no-colour-cast")
    assert "white point 0.6 " in err and "Spike-Zoo" in err
    assert abs(float(x.mean()) - float(intensity.mean())) < 0.02


class _Info:
    def __init__(self, extra):
        self.extra = extra


class _Src:
    def __init__(self, extra):
        self.info = _Info(extra)


@pytest.mark.parametrize("white, extra, alpha, expect", [
    (0.55, {"display_transfer": "linear"}, None, ECOSYSTEM_RATE),
    (0.49, {"display_transfer": "linear"}, None, ECOSYSTEM_RATE),  # inside the band (0.48 .. 0.75)
    (0.74, {"display_transfer": "linear"}, None, ECOSYSTEM_RATE),
    (0.47, {"display_transfer": "linear"}, None, 0.47),
    (0.76, {"display_transfer": "linear"}, None, 0.76),
    (0.031, {"display_transfer": "linear"}, None, 0.031),  # a dark real capture
    (0.55, {"display_transfer": "linear", "sidecar": "x.toml"}, None, 0.55),
    (0.55, {"display_transfer": "srgb"}, None, 0.55),
    (0.55, {"display_transfer": "linear"}, np.array([1.0, 1.0, 1.0]), 0.55),
])
def test_the_rule(white, extra, alpha, expect):
    got, how = ecosystem_white(white, _Src(extra), alpha)
    assert got == pytest.approx(expect)
    assert ("Spike-Zoo" in how) == (got != white)


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_a_dark_captures_white_is_its_brightest_rate_not_its_count_levels(cfa):
    """0.08 spikes per tick at the brightest: a 10-tick window holds 0 to 1 spikes there, and the percentile of the
    count levels read ~0.15 (frames at half brightness); over windows that hold 4 spikes at the white it reads the
    rate. A bright capture keeps its 10-tick windows."""
    from spikeview.classical.colour_cast import estimate_white
    from spikeview.io.source import ArraySource

    ramp = np.minimum(np.linspace(0.05, 1.0, 96) / 0.9, 1.0)
    intensity = np.broadcast_to(ramp[None, :], (64, 96))
    for peak in (0.08, 0.6):
        src = ArraySource(_integrate_and_fire(peak * intensity, 200), cfa=cfa)
        alpha = None if cfa is None else np.ones(3)
        detail: dict = {}
        white = estimate_white(src, alpha, window=10, eta=1.0, detail=detail)
        # the top level's spread still lifts it a little (its 10 % of photosites sit on one rate): 10-tick windows
        # read 0.15 at 0.08 (1.9x)
        assert peak <= white <= 1.25 * peak, (peak, white)
        assert (detail["ticks"] > 10) == (peak < 0.5)
    # the bound: never longer than the 7 windows the guided default pools
    src = ArraySource(_integrate_and_fire(0.01 * intensity, 200), cfa=cfa)
    detail = {}
    estimate_white(src, None if cfa is None else np.ones(3), window=10, eta=1.0, detail=detail)
    assert detail["ticks"] == 70


def test_the_white_point_line_says_the_longer_windows(tmp_path, capsys):
    path, _ = _capture(tmp_path, 0.04, sidecar=True)
    _, err = _run(path, tmp_path, capsys)
    assert "-tick windows (a 30-tick window holds under 3 spikes at the white" in err  # 30 ticks: 1.2 spikes at 0.04


def test_reconstruct_says_which_tick_it_took(tmp_path, capsys):
    """Without --at the CLI takes the window at the middle of the capture, and says so (the preset records it too)."""
    path, _ = _capture(tmp_path, 0.6, sidecar=True)
    out = tmp_path / "mid.npy"
    assert main(["reconstruct", str(path), "--method", "tfp", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "(the window centred on tick 150, the middle of the capture: --at T for another)" in said
    assert main(["reconstruct", str(path), "--method", "tfp", "--at", "40", "--out", str(out), "--overwrite"]) == 0
    assert "(the window centred on tick 40) to" in capsys.readouterr().out


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_the_sampler_keeps_the_exposure_of_the_window_length_white(cfa):
    """A dark capture's display white comes from longer windows; the guided sampler's exposure stays that of the
    reconstruction's own windows (what it was tuned on), in the CLI, the app's jobs and a Dask store's state alike."""
    from spikeview.classical.colour_cast import estimate_white
    from spikeview.cluster._compute import state_from_attrs, state_to_attrs
    from spikeview.guided.observation import EXPOSURE_LEVEL, exposed_eta
    from spikeview.io.source import ArraySource
    from spikeview.pipeline import guided_scale, prepare_sequence, sampler_params
    from spikeview.recipe import Recipe

    ramp = np.minimum(np.linspace(0.05, 1.0, 96) / 0.9, 1.0)
    src = ArraySource(_integrate_and_fire(0.08 * np.broadcast_to(ramp[None, :], (64, 96)), 200), cfa=cfa)
    recipe = Recipe()
    state = prepare_sequence(src, recipe, warn=False)
    detail: dict = {}
    estimate_white(src, state.alpha, window=10, eta=recipe.classical.eta, detail=detail)
    assert state.white < 0.8 * detail["window_white"]  # the display white: longer windows, lower
    assert state.exposure_white == pytest.approx(detail["window_white"])
    assert state.sampler_white == state.exposure_white
    if cfa is None:  # monochrome: no C carries an exposure, the sampler sees the plain rates
        assert guided_scale(state) == 1.0 and sampler_params(recipe, state) is recipe.guided
    else:
        assert guided_scale(state) == pytest.approx(state.exposure_white / EXPOSURE_LEVEL)
        assert sampler_params(recipe, state).eta == pytest.approx(exposed_eta(recipe.classical.eta, state.exposure_white))
    again = state_from_attrs(state_to_attrs(state))
    assert again.white == state.white and again.exposure_white == state.exposure_white
    assert state.tfi_reach is not None and again.tfi_reach == state.tfi_reach  # TFI's search too (pipeline.tfi_reach)
    # a bright capture has one white
    bright = prepare_sequence(ArraySource(_integrate_and_fire(0.6 * np.broadcast_to(ramp[None, :], (64, 96)), 200),
                                          cfa=cfa), recipe, warn=False)
    assert bright.exposure_white is None and "exposure_white" not in state_to_attrs(bright)
    assert bright.tfi_reach is None and "tfi_reach" not in state_to_attrs(bright)


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_a_capture_without_spikes_says_so_in_its_white_point_line(cfa):
    """An all-zero capture took a white point of 1 'by the 99.9th percentile', which was 0: it says its frames are
    black whatever the white point."""
    from spikeview.io.source import ArraySource
    from spikeview.pipeline import prepare_sequence
    from spikeview.recipe import Recipe

    state = prepare_sequence(ArraySource(np.zeros((40, 16, 16), np.uint8), cfa=cfa), Recipe(), warn=False)
    assert "has no spikes in the windows sampled" in state.white_how
    state = prepare_sequence(ArraySource((np.random.default_rng(0).random((40, 16, 16)) < 0.3).astype(np.uint8), cfa=cfa),
                             Recipe(), warn=False)
    assert "no spikes" not in state.white_how
