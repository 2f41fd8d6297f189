"""Camera calibration (spikeview.classical.calibration, ``spikeview calibrate``, ``--camera``) on simulated dark and flat captures."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from spikeview.classical.calibration import CameraProfile, attach, correct_rates, measure
from spikeview.errors import ParameterError

N = 32
GAINS = (0.55, 1.0, 0.45)
HOT = 0.01


def _cfg(cfa: str, n_ticks: int, **over):
    from spikeview.sim import SimConfig

    return SimConfig(n_ticks=n_ticks, seed=5, cfa=cfa, spectral_gains=GAINS, hot_pixels=HOT, gt_every=5, **over)


def _still(value: float, cfa: str, n_ticks: int):
    from spikeview.sim import simulate
    from spikeview.sim.scenes import StaticScene

    return simulate(StaticScene(np.full((N, N, 3), value, np.float32), srgb=False), _cfg(cfa, n_ticks))


def _scene(cfa: str, n_ticks: int = 60):
    """A textured colour scene on the same sensor (same seed: the same fixed pattern)."""
    from spikeview.sim import MotionScene, simulate

    rng = np.random.default_rng(3)
    img = np.kron(rng.random((8, 8, 3)), np.ones((8, 8, 1))).astype(np.float32) * 0.8 + 0.1
    return simulate(MotionScene(img, size=(N, N), pan=(0.0, 0.0)), _cfg(cfa, n_ticks))


@pytest.fixture(scope="module", params=["RGGB", "none"])
def sensor(request):
    cfa = request.param
    from spikeview.sim.simulator import SensorPattern

    pat = SensorPattern.build(_cfg(cfa, 10), N, N)
    dark, flat = _still(0.0, cfa, 3000), _still(0.8, cfa, 1500)
    return cfa, pat, dark, flat, measure(dark, flat)


def test_profile_finds_the_sensors_hot_pixels_gain_and_colour(sensor):
    cfa, pat, _dark, _flat, prof = sensor
    true_hot = pat.dark > 20 * np.median(pat.dark)
    assert true_hot.sum() >= 3
    assert np.array_equal(prof.hot, true_hot)  # every hot pixel, and nothing else
    true_gain = (pat.drive * pat.cap_ratio / pat.theta).astype(np.float64)
    ok = ~true_hot
    for c in np.unique(pat.channel):
        m = (pat.channel == c) & ok
        g = true_gain[m] / true_gain[m].mean()
        assert np.corrcoef(g, prof.gain[m])[0, 1] > 0.97
        assert np.abs(prof.gain[m] - g).max() < 0.03
    if cfa == "none":
        assert prof.colour_response is None
        with pytest.raises(ParameterError, match="no colour response"):
            prof.colour_gains()
    else:
        np.testing.assert_allclose(prof.colour_gains(), [1 / GAINS[0], 1.0, 1 / GAINS[2]], rtol=0.02)
    assert prof.stats["dark_rate_mean"] == pytest.approx(float(np.median(pat.dark)), rel=0.2)


def test_correction_flattens_a_flat_capture_and_fills_hot_pixels(sensor):
    cfa, pat, _dark, flat, prof = sensor  # noqa: F841
    from spikeview.classical.calibration import mean_rates

    raw = mean_rates(flat)
    fixed = prof.correct(raw)
    assert fixed.dtype == np.float32 and fixed.shape == raw.shape
    for c in np.unique(pat.channel):
        m = pat.channel == c
        spread_raw = raw[m].std() / raw[m].mean()
        spread = fixed[m].std() / fixed[m].mean()
        assert spread_raw > 0.05 and spread < 0.01, (spread_raw, spread)  # hot pixels included: filled
    # unbiased: the 10-tick windows of the dark capture correct to 0 on average (not clipped up at 0)
    wins = np.stack([prof.correct(_dark.count(a, a + 10) / 10.0) for a in range(0, _dark.n_frames, 10)])
    assert abs(float(wins.mean())) < 1e-5 and wins.min() < 0
    stack = prof.correct(np.stack([raw, raw]))  # (T, H, W) as well
    np.testing.assert_array_equal(stack[1], fixed)
    with pytest.raises(ParameterError, match="32x32"):
        prof.correct(raw[:, :16])


def test_save_load_round_trip_and_bad_profiles_refused(sensor, tmp_path):
    cfa, _pat, _dark, _flat, prof = sensor
    path = prof.save(tmp_path / "cam.toml")
    back = CameraProfile.load(path)
    for name in ("dark", "gain", "hot"):
        np.testing.assert_array_equal(getattr(back, name), getattr(prof, name))
    assert (back.width, back.height, back.cfa) == (N, N, prof.cfa)
    if prof.colour_response is not None:
        np.testing.assert_array_equal(back.colour_response, prof.colour_response)

    def refused(p, needle):
        with pytest.raises(ParameterError, match=needle) as e:
            CameraProfile.load(p)
        assert "\n" not in str(e.value) and str(e.value).endswith(".")

    def with_maps(name, **maps):
        """A copy of the profile whose .npz holds ``maps`` (and whose TOML names it with the right hash)."""
        import io

        z = {"dark": prof.dark, "gain": prof.gain, "hot": prof.hot, **maps}
        buf = io.BytesIO()
        np.savez(buf, **z)
        (tmp_path / f"{name}.npz").write_bytes(buf.getvalue())
        text = path.read_text().replace('arrays = "cam.npz"', f'arrays = "{name}.npz"')
        text = text.replace(text.split('arrays_sha256 = "')[1].split('"')[0], hashlib.sha256(buf.getvalue()).hexdigest())
        (tmp_path / f"{name}.toml").write_text(text)
        return tmp_path / f"{name}.toml"

    refused(with_maps("nan", gain=np.where(prof.hot, np.nan, prof.gain) * np.ones_like(prof.gain)), "gain map")
    refused(with_maps("zero", gain=np.zeros_like(prof.gain)), "gain map")
    refused(with_maps("small", dark=prof.dark[:8]), "dark map")
    (tmp_path / "text.toml").write_text("this is not a profile\n")
    refused(tmp_path / "text.toml", "not valid TOML")
    (tmp_path / "other.toml").write_text("[guided]\nk = 20\n")
    refused(tmp_path / "other.toml", "not a camera profile")
    (tmp_path / "bin.toml").write_bytes(b"\x00\xff\xfe garbage")
    refused(tmp_path / "bin.toml", "bin.toml")
    (tmp_path / "cam.npz").write_bytes((tmp_path / "cam.npz").read_bytes() + b"x")
    refused(path, "SHA-256")
    (tmp_path / "cam.npz").unlink()
    refused(path, "missing")


def test_profile_refuses_another_geometry_cfa_or_flip(sensor):
    from spikeview.io.source import ArraySource

    cfa, _pat, _dark, _flat, prof = sensor
    other = "GRBG" if cfa == "RGGB" else "RGGB"
    cases = [(ArraySource(np.zeros((4, N, N + 2), np.uint8), cfa=None if cfa == "none" else cfa), f"{N}x{N}"),
             (ArraySource(np.zeros((4, N, N), np.uint8), cfa=other), "CFA"),
             (ArraySource(np.zeros((4, N, N), np.uint8), cfa=None if cfa == "none" else cfa,
                          info=None), "flip")]
    src = cases[2][0]
    src.info = src.info.replace(flip_vertical=not prof.flip_vertical)
    for s, needle in cases:
        with pytest.raises(ParameterError, match=needle) as e:
            attach(s, prof)
        assert "\n" not in str(e.value)
        assert getattr(s.info, "camera", None) is None


def test_classical_and_guided_see_the_same_corrected_rates(sensor):
    """The one correction: TFP frames and the guided observation are corrected alike (and not without a profile)."""
    from spikeview.classical.reconstruct import ClassicalConfig, reconstruct_frame
    from spikeview.classical.tfp import tfp
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.window import observe_window

    cfa, _pat, _dark, _flat, prof = sensor
    cap = _scene(cfa)
    plain_y = tfp(cap, 30, 10)
    cfg = ClassicalConfig(colour_cast=False, demosaic="bilinear")
    before = reconstruct_frame(cap, 30, cfg)
    obs_before = observe_window(cap, 30, GuidedConfig(temporal_radius=0), None, plan=False).obs.y
    attach(cap, prof)
    try:
        want = prof.correct(plain_y)
        after = reconstruct_frame(cap, 30, cfg)
        from spikeview.classical.demosaic import demosaic

        np.testing.assert_allclose(after, want if cfa == "none" else demosaic(want, cfa, "bilinear"), rtol=1e-6, atol=1e-7)
        assert not np.allclose(after, before)
        obs = observe_window(cap, 30, GuidedConfig(temporal_radius=0), None, plan=False).obs.y
        # a dark rate or flat field moves the rates off the count grid: the observation keeps the negative values the
        # dark subtraction leaves (clipped at 0 they would lift the black of each channel by its own noise: a tint)
        lo = -1.0 if prof.moves_rates() else 0.0
        np.testing.assert_allclose(obs, np.clip(want, lo, 1), atol=1e-7)
        if prof.moves_rates() and (want < 0).any():
            assert obs.min() < 0
        assert not np.allclose(obs, obs_before)
        np.testing.assert_array_equal(correct_rates(cap, plain_y), want)
    finally:
        cap.info = cap.info.replace(camera=None)


def test_profile_improves_tfp_on_a_capture_with_threshold_spread_and_hot_pixels(sensor):
    from spikeview.bench.score import score
    from spikeview.pipeline import exposure_mapping, prepare_sequence, reconstruct_windows, recipe_for_state
    from spikeview.recipe import Recipe

    cfa, _pat, _dark, _flat, prof = sensor
    cap = _scene(cfa, n_ticks=200)
    centres = [45, 105, 155]

    def run(with_profile: bool, wb: str = "auto") -> float:
        cap.info = cap.info.replace(camera=None)
        if with_profile:
            attach(cap, prof)
        recipe = Recipe().with_values({"run.method": "tfp", "classical.window": 40, "classical.white_balance": wb})
        state = prepare_sequence(cap, recipe, warn=False)
        recipe = recipe_for_state(recipe, state)
        expose = exposure_mapping(recipe, state, "x.npy")[1]
        frames = [expose(f) for f in reconstruct_windows(cap, centres, recipe, state)]
        cap.info = cap.info.replace(camera=None)
        def truth(c):
            gt = cap.gt_at(c)
            return gt @ np.array([0.2126, 0.7152, 0.0722], np.float32) if cfa == "none" else gt  # mono: luminance

        return float(np.mean([score(f, truth(c))[0] for f, c in zip(frames, centres)]))

    without, with_ = run(False), run(True)
    assert with_ >= without + 1.0, (without, with_)
    if cfa != "none":
        assert run(True, "profile") >= without + 1.0


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_cli_calibrate_info_and_reconstruct_with_camera(tmp_path, capsys, cfa):
    from spikeview.cli.main import main
    from spikeview.recipe import Recipe
    from spikeview.sim import simulate_to_file
    from spikeview.sim.scenes import StaticScene

    for name, value, ticks in (("dark", 0.0, 2000), ("flat", 0.8, 1000)):
        simulate_to_file(StaticScene(np.full((N, N, 3), value, np.float32), srgb=False), _cfg(cfa, ticks),
                         tmp_path / f"{name}.dat")
    rng = np.random.default_rng(3)
    img = np.kron(rng.random((8, 8, 3)), np.ones((4, 4, 1))).astype(np.float32)
    simulate_to_file(StaticScene(img, srgb=False), _cfg(cfa, 100), tmp_path / "cap.dat")
    prof = tmp_path / "cam.toml"
    assert main(["calibrate", "--dark", str(tmp_path / "dark.dat"), "--flat", str(tmp_path / "flat.dat"),
                 "--out", str(prof)]) == 0
    out = capsys.readouterr()
    assert "hot pixel" in out.err and "flat:" in out.err and prof.is_file() and prof.with_suffix(".npz").is_file()
    assert ("colour response" in out.out) == (cfa != "none")
    assert main(["info", str(tmp_path / "cap.dat"), "--camera", str(prof)]) == 0
    assert "camera:      camera profile cam.toml" in capsys.readouterr().out
    res = tmp_path / "x.npy"  # the default white balance (auto) takes the profile's colour response
    assert main(["reconstruct", str(tmp_path / "cap.dat"), "--camera", str(prof), "--at", "50", "--out", str(res)]) == 0
    err = capsys.readouterr().err
    assert ("auto → profile" in err) == (cfa != "none"), err
    if cfa != "none":  # ... the same gains, the same pixels as asking for it
        assert main(["reconstruct", str(tmp_path / "cap.dat"), "--camera", str(prof), "--white-balance", "profile",
                     "--at", "50", "--out", str(tmp_path / "p.npy")]) == 0
        assert "white balance profile" in capsys.readouterr().err
        np.testing.assert_array_equal(np.load(tmp_path / "p.npy"), np.load(res))
    rec = Recipe.load(str(res) + ".preset.toml")
    assert rec.stream.camera == str(prof.absolute())
    assert main(["reconstruct", str(tmp_path / "cap.dat"), "--preset", str(res) + ".preset.toml", "--out",
                 str(tmp_path / "y.npy")]) == 0  # the preset re-runs with the profile: the same pixels
    np.testing.assert_array_equal(np.load(tmp_path / "y.npy"), np.load(res))
    capsys.readouterr()
    # refusals: one sentence each, no traceback
    (tmp_path / "junk.toml").write_text("garbage = = =\n")
    np.save(tmp_path / "d0.npy", np.zeros((50, N, N), np.uint8))
    simulate_to_file(StaticScene(np.zeros((N, N + 8, 3), np.float32), srgb=False), _cfg(cfa, 20), tmp_path / "wide.dat")
    bad = [(["info", str(tmp_path / "wide.dat"), "--camera", str(prof)], f"{N}x{N}"),
           (["reconstruct", str(tmp_path / "cap.dat"), "--camera", str(tmp_path / "junk.toml"), "--out",
             str(tmp_path / "z.npy")], "junk.toml"),
           (["reconstruct", str(tmp_path / "cap.dat"), "--camera", str(tmp_path / "nothere.toml"), "--out",
             str(tmp_path / "z.npy")], "nothere.toml"),
           (["calibrate", "--out", str(tmp_path / "p.toml")], "--dark"),
           (["calibrate", "--flat", str(tmp_path / "dark.dat"), "--out", str(tmp_path / "p.toml")], "too dark"),
           # the input's sidecar (how to read it) is never replaced, even with --overwrite
           (["calibrate", "--dark", str(tmp_path / "dark.dat"), "--out", str(tmp_path / "dark.dat.toml"),
             "--overwrite"], "the sidecar of an input of the run (dark.dat"),
           # ... nor written where there is none yet: the capture would read the profile as its sidecar
           (["calibrate", "--dark", str(tmp_path / "d0.npy"), "--out", str(tmp_path / "d0.npy.toml")],
            "the sidecar of an input of the run (d0.npy"),
           # an existing profile: it exists (not "the settings file of an earlier run whose output ... is gone")
           (["calibrate", "--dark", str(tmp_path / "dark.dat"), "--out", str(prof)], "cam.toml: the file already exists")]
    if cfa != "none":
        bad.append((["reconstruct", str(tmp_path / "cap.dat"), "--cfa", "GRBG", "--camera", str(prof), "--out",
                     str(tmp_path / "z.npy")], "CFA"))
    for argv, needle in bad:
        assert main(argv) != 0, argv
        text = capsys.readouterr().err.strip()
        assert text.startswith("spikeview: error:") and needle in text and "Traceback" not in text, text
        assert len(text.splitlines()) == 1, text
    assert main(["info", str(tmp_path / "dark.dat")]) == 0  # its sidecar still says how to read it
    capsys.readouterr()


def test_the_plan_turns_q_off_on_rates_a_profile_moved_off_the_tfp_grid(sensor):
    """Q rounds to the 1/Δτ levels of raw counts; a dark rate or flat field moves the corrected rates between them
    (a colour shift of 3.8° and −2 dB on a calibrated capture): the plan turns Q off and says why; a profile of hot
    pixels only (the capture's own) moves nothing; a hand-set Q stays."""
    from spikeview.classical.calibration import capture_profile
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.window import observe_window

    cfa, _pat, _dark, _flat, prof = sensor
    assert prof.moves_rates() == "dark rate and flat field"
    from spikeview.sim import MotionScene, simulate

    rng = np.random.default_rng(3)
    img = np.kron(rng.random((8, 8, 3)), np.ones((4, 4, 1))).astype(np.float32) * 0.12 + 0.02  # a dark scene
    cap = simulate(MotionScene(img, size=(N, N), pan=(0.0, 0.0)), _cfg(cfa, 60))
    hot_only = capture_profile(cap)
    assert hot_only is None or hot_only.moves_rates() is None
    alpha = None if cfa == "none" else np.ones(3)
    low = GuidedConfig(temporal_radius=0)  # one 10-tick window: a low count, where Q is on by the rate rule
    plain = observe_window(cap, 30, low, alpha).plan
    assert plain.quantise and "low count" in plain.reasons["quantise"]
    attach(cap, prof)
    try:
        w = observe_window(cap, 30, low, alpha)
        assert w.whole.corrected and not w.plan.quantise
        assert "camera profile" in w.plan.reasons["quantise"] and "dark rate and flat field" in w.plan.reasons["quantise"]
        forced = observe_window(cap, 30, GuidedConfig(temporal_radius=0, quantise=True), alpha).plan
        assert forced.quantise
        roi = observe_window(cap, 30, low, alpha, roi=(8, 8, 16, 16))
        assert roi.obs.corrected and not roi.plan.quantise  # a region of it too
    finally:
        cap.info = cap.info.replace(camera=None)


def test_the_guided_frame_keeps_the_profiles_balance(sensor):
    """With a profile's colour response (auto → profile) the guided frame's channel means are kept at the corrected
    data's (its clip at 0 would lift each channel's black by its own noise): the state says so, for recorded gains too,
    and the plan's balance row names the profile. Monochrome: a gray frame, nothing to keep."""
    from spikeview.pipeline import plan_window, prepare_sequence
    from spikeview.recipe import Recipe

    from spikeview.sim import MotionScene, simulate

    cfa, _pat, _dark, _flat, prof = sensor
    rng = np.random.default_rng(3)
    img = np.kron(rng.random((8, 8, 3)), np.ones((4, 4, 1))).astype(np.float32) * 0.12 + 0.02  # a dark scene
    cap = simulate(MotionScene(img, size=(N, N), pan=(0.0, 0.0)), _cfg(cfa, 60))
    attach(cap, prof)
    try:
        recipe = Recipe().with_values({"run.method": "guided"})
        state = prepare_sequence(cap, recipe, warn=False)
        plan = plan_window(cap, recipe, 30, state=state).plan
        if cfa == "none":
            assert not state.keep_balance and plan.reasons["balance"].startswith("none")
            return
        assert state.keep_balance and "profile" in (state.white_balance or "")
        recorded = recipe.with_values({"classical.alpha": [float(v) for v in state.alpha]})
        assert prepare_sequence(cap, recorded, warn=False).keep_balance
        # on dark-subtracted rates every white balance keeps it: the clip at 0 lifts each channel's black whatever the gains
        assert prepare_sequence(cap, recipe.with_values({"classical.white_balance": "white-patch"}),
                                warn=False).keep_balance
        assert plan.diffusion and plan.balance and "camera profile" in plan.reasons["balance"]
    finally:
        cap.info = cap.info.replace(camera=None)
