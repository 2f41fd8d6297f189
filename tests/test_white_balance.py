"""White balance beyond gray-world (spikeview.classical.white_balance, ``--white-balance``)."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.classical import white_balance as wb
from spikeview.classical.colour_cast import sequence_white_balance
from spikeview.classical.config import ClassicalConfig
from spikeview.errors import ParameterError
from spikeview.io.source import ArraySource

TINT = np.array([0.55, 1.0, 0.45])  # a sensor response (issue 26)


def _colourful(seed: int = 0, n: int = 64) -> np.ndarray:
    """A scene whose mean is green but whose edges are gray: a flat green field (no edges) beside a gray texture."""
    rng = np.random.default_rng(seed)
    img = np.empty((n, n, 3))
    img[:, : n // 2] = [0.1, 0.6, 0.1]  # flat: no edges, no highlights
    tex = 0.2 + 0.6 * (rng.random((n // 8, n // 2 // 8)) > 0.5)
    img[:, n // 2:] = np.kron(tex, np.ones((8, 8)))[..., None]
    img[0, -1] = 0.95  # one white highlight cell: the white-patch estimate's patch
    return img


def _mosaic(rgb: np.ndarray, cfa: str) -> np.ndarray:
    """(h, w, 3) cell colours → (2h, 2w) mosaic with ``cfa``."""
    h, w, _ = rgb.shape
    out = np.zeros((2 * h, 2 * w))
    idx = {"R": 0, "G": 1, "B": 2}
    for k, ch in enumerate(cfa):
        out[k // 2::2, k % 2::2] = rgb[..., idx[ch]]
    return out


@pytest.mark.parametrize("method", wb.ESTIMATORS)
def test_every_estimator_is_equivariant_to_channel_gains(method):
    # est(D·I) = D·est(I): why no estimator can tell a tinted scene from a tinted sensor (module docstring)
    img = np.random.default_rng(1).random((24, 24, 3)) * 0.8
    d = np.array([0.5, 1.0, 0.3])
    a, b = wb.illuminant(img, method), wb.illuminant(img * d, method)
    assert wb.angle_deg(a * d, b) < 1e-4


@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
def test_edges_find_the_sensor_tint_where_gray_world_takes_the_scene_for_it(cfa):
    scene = _colourful()
    raw = _mosaic(scene * TINT * 0.5, cfa)
    img = wb.cells_rgb(raw, cfa)
    np.testing.assert_allclose(img, scene * TINT * 0.5)
    gw, ge, co = (wb.illuminant(img, m) for m in ("gray-world", "gray-edge", "combined"))
    assert wb.angle_deg(ge, TINT) < 4  # the edges are mostly gray (the field's border is not)
    assert wb.angle_deg(co, TINT) < 4
    assert wb.angle_deg(gw, TINT) > 10  # the green field pulls the mean
    choice = wb.choose(img, "auto")
    assert choice.method == "combined+typical" and "colourful" in choice.reason and "typical" in choice.reason
    assert wb.angle_deg(choice.illuminant, TINT) < 4
    gray = wb.choose(wb.cells_rgb(_mosaic(np.repeat(scene.mean(axis=-1, keepdims=True), 3, -1) * TINT, cfa), cfa), "auto")
    assert gray.method == "gray-world" and "averages to gray" in gray.reason


def test_auto_keeps_gray_world_when_the_estimate_is_too_noisy():
    img = _colourful() * TINT
    noisy = [img * (1 + 0.3 * np.random.default_rng(s).standard_normal(img.shape)) ** 2 for s in (1, 2)]
    quiet = wb.choose(img, "auto", (img, img))
    assert quiet.method == "combined+typical"
    assert wb.choose(img, "auto", tuple(noisy)).method in ("gray-world", "combined+typical")  # decided by the numbers
    far = (img, img * np.array([3.0, 1.0, 0.2]))  # halves that disagree by far more than the estimates do
    loud = wb.choose(img, "auto", far)
    assert loud.method == "gray-world" and "too noisy" in loud.reason


@pytest.mark.parametrize("text, expected", [("auto", "auto"), (" Gray-Edge ", "gray-edge"), ("1.5,1,2", [1.5, 1.0, 2.0])])
def test_parse(text, expected):
    assert wb.parse_white_balance(text) == expected


@pytest.mark.parametrize("text", ["purple", "1,2", "1,0,2", "1,nan,2", "a,b,c", ""])
def test_parse_refuses_in_one_sentence(text):
    with pytest.raises(ParameterError, match="--white-balance") as e:
        wb.parse_white_balance(text)
    assert str(e.value).endswith(").") and "\n" not in str(e.value)
    with pytest.raises(ParameterError, match="classical.white_balance"):
        ClassicalConfig(white_balance=text)


def _source(scene: np.ndarray, cfa: str | None, ticks: int = 64, seed: int = 0) -> ArraySource:
    """Integrate-and-fire spikes of a static mosaic (rates = ``scene`` per tick)."""
    rates = _mosaic(scene, cfa) if cfa else scene.mean(axis=-1).repeat(2, 0).repeat(2, 1)
    v = np.random.default_rng(seed).random(rates.shape)
    out = np.zeros((ticks,) + rates.shape, dtype=np.uint8)
    for t in range(ticks):
        v += rates
        out[t] = v >= 1
        v -= out[t]
    return ArraySource(out, cfa=cfa)


@pytest.mark.parametrize("cfa", ["RGGB", "BGGR"])
def test_sequence_white_balance_on_spikes(cfa):
    src = _source(_colourful() * TINT * 0.8, cfa)
    means = {m: sequence_white_balance(src, ClassicalConfig(white_balance=m), warn=False) for m in ("gray-world", "auto")}
    a_gw, _, why_gw = means["gray-world"]
    a_auto, _, why_auto = means["auto"]
    assert "gray-world" in why_gw and "combined" in why_auto and "typical" in why_auto
    # the gains undo the tint: α·tint is gray for auto, not for gray-world
    assert wb.angle_deg(a_auto * TINT, np.ones(3)) < 3.0  # the typical response is 3.3° off this sensor
    assert wb.angle_deg(a_gw * TINT, np.ones(3)) > 10
    fixed = sequence_white_balance(src, ClassicalConfig(white_balance="2,1,3"), warn=False)
    np.testing.assert_array_equal(fixed[0], [2.0, 1.0, 3.0])
    with pytest.raises(ParameterError, match="--camera"):
        sequence_white_balance(src, ClassicalConfig(white_balance="profile"))


def test_mono_has_no_white_balance():
    src = _source(_colourful(), None)
    for m in ("auto", "gray-edge", "1,2,3"):
        assert sequence_white_balance(src, ClassicalConfig(white_balance=m)) == (None, None, None)


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_cli_white_balance_flag_prints_the_choice_and_records_it(tmp_path, capsys, cfa):
    from spikeview.cli.main import main
    from spikeview.io.plain import write_plain
    from spikeview.recipe import Recipe

    src = _source(_colourful() * TINT * 0.8, None if cfa == "none" else cfa)
    path = tmp_path / "cap.dat"
    write_plain(path, src.read(0, src.n_frames))
    geom = ["--width", "128", "--height", "128", "--cfa", cfa]  # 64² cells of 2×2 photosites
    outs = {}
    for m in ("gray-world", "auto"):
        out = tmp_path / f"{m}.npy"
        assert main(["reconstruct", str(path), *geom, "--white-balance", m, "--out", str(out)]) == 0
        err = capsys.readouterr().err
        rec = Recipe.load(str(out) + ".preset.toml")
        assert rec.classical.white_balance == m
        outs[m] = np.load(out)
        if cfa == "none":
            assert "white balance" not in err and rec.classical.alpha is None
        else:
            assert ("white balance auto → combined" if m == "auto" else "white balance gray-world") in err
            assert rec.classical.alpha is not None
    if cfa == "none":
        np.testing.assert_array_equal(outs["gray-world"], outs["auto"])
    else:
        assert not np.allclose(outs["gray-world"], outs["auto"])
    assert main(["reconstruct", str(path), *geom, "--white-balance", "teal", "--out", str(tmp_path / "x.npy")]) != 0
    err = capsys.readouterr().err.strip()
    assert err.startswith("spikeview: error:") and "--white-balance" in err and "Traceback" not in err


@pytest.mark.parametrize("cfa", ["RGGB", "GRBG"])
def test_auto_keeps_gray_world_on_featureless_noise(cfa):
    # equal rates in every channel and no texture: edges and highlights are noise; with both greens averaged G's noise
    # is half the others' and the edge estimate once took that for colour (auto chose "combined" here)
    rng = np.random.default_rng(4)
    src = ArraySource((rng.random((200, 96, 96)) < 0.2).astype(np.uint8), cfa=cfa)
    a, _, why = sequence_white_balance(src, ClassicalConfig(white_balance="auto"))
    assert "gray-world" in why and wb.angle_deg(a, np.ones(3)) < 1.0


def test_large_sequence_images_are_binned():
    img = np.random.default_rng(0).random((600, 300, 3))
    b = wb.binned(img)
    assert b.shape == (200, 100, 3)
    np.testing.assert_allclose(b[0, 0], img[:3, :3].mean(axis=(0, 1)))
    assert wb.binned(img[:200]) is not img  # 200 rows, 300 cols: k = 2
    small = img[:100, :100]
    assert wb.binned(small) is small


def _coloured_edges(seed: int = 0, n: int = 64) -> np.ndarray:
    """A scene whose edges and highlights are coloured too: a texture of two yellow-greens (no neutral anywhere)."""
    rng = np.random.default_rng(seed)
    tex = 0.2 + 0.6 * rng.random((n // 4, n // 4, 1))
    hue = np.where(rng.random((n // 4, n // 4, 1)) > 0.5, [0.7, 1.0, 0.6], [0.95, 1.0, 0.5])
    return np.kron(tex * hue, np.ones((4, 4, 1)))


def test_toward_typical_moves_a_near_estimate_and_keeps_a_far_sure_one():
    typ = np.array(wb.TYPICAL_RESPONSE)
    same, w = wb.toward_typical(typ * 3, 0.25)
    np.testing.assert_allclose(same, typ, rtol=0.005)  # the neutral component, 17° away, moves it by 0.1 %
    near = typ * [1.2, 1, 0.85]  # 16 % and 15 % off: most of the way back
    e, w = wb.toward_typical(near, wb.COMBINED_SIGMA)
    assert w > 0.7 and wb.angle_deg(e, typ) < 0.3 * wb.angle_deg(near, typ)
    far = np.array([1.5, 1.0, 2.0])  # a sensor unlike the typical one, estimated surely: kept
    e, w = wb.toward_typical(far, 0.1)
    assert w < 0.05 and wb.angle_deg(e, far) < 1.0
    # a less sure estimate of the same moves further: the prior's share grows with the estimate's σ
    assert wb.toward_typical(near, 0.6)[1] > wb.toward_typical(near, 0.1)[1]
    bad = np.array([0.0, 1.0, 0.5])
    e, w = wb.toward_typical(bad, 0.25)
    assert w == 0 and e is not None and np.array_equal(e, bad)


def test_an_estimate_near_neutral_moves_toward_neutral_not_the_typical_response():
    """A file made from display-referred RGB frames (the ecosystem's simulators) has no cast: an estimate a few
    degrees off R = G = B moves toward it (the prior's neutral component), not toward the typical response 17° away
    (which pulled an independent simulator's captures 34-47 % of the way, 5.5° off); one halfway between the two
    moves less than half way to either."""
    typ = np.array(wb.TYPICAL_RESPONSE)
    near = np.array([1.06, 1.0, 0.92])  # 4.5° off neutral
    e, w = wb.toward_typical(near, wb.COMBINED_SIGMA)
    assert wb.angle_deg(e, np.ones(3)) < 0.4 * wb.angle_deg(near, np.ones(3)), wb.angle_deg(e, np.ones(3))
    assert wb.angle_deg(e, np.ones(3)) < 0.2 * wb.angle_deg(e, typ)
    assert "neutral response" in wb._pulled(near, e, w)
    near_typ = typ * [1.2, 1, 0.85]
    assert "typical spike-camera response" in wb._pulled(near_typ, *wb.toward_typical(near_typ, 0.25))
    between = np.sqrt(typ)  # halfway in log chromaticity
    e, w = wb.toward_typical(between, wb.COMBINED_SIGMA)
    assert wb.angle_deg(e, between) < 0.5 * wb.angle_deg(between, typ)


@pytest.mark.parametrize("cfa", ["RGGB", "BGGR"])
def test_auto_pulls_a_scene_with_coloured_edges_toward_the_typical_response(cfa):
    # every estimator takes the scene's green-yellow for the sensor's cast; the typical response breaks the tie
    scene = _coloured_edges()
    img = wb.cells_rgb(_mosaic(scene * TINT * 0.5, cfa), cfa)
    co = wb.illuminant(img, "combined")
    assert wb.angle_deg(co, TINT) > 8
    got = wb.choose(img, "auto", (img, img))
    assert got.method == "combined+typical" and "pulled" in got.reason and "R 0.6 / G 1 / B 0.5" in got.reason
    assert wb.angle_deg(got.illuminant, TINT) < 5
    src = _source(scene * TINT * 0.8, cfa)
    a, _, why = sequence_white_balance(src, ClassicalConfig(white_balance="auto"), warn=False)
    assert "typical" in why and wb.angle_deg(a * TINT, np.ones(3)) < 5
    t, _, why_t = sequence_white_balance(src, ClassicalConfig(white_balance="typical"), warn=False)
    assert "typical" in why_t and wb.angle_deg(t * np.array(wb.TYPICAL_RESPONSE), np.ones(3)) < 1e-6


def test_auto_keeps_gray_world_for_a_neutral_sensor_on_a_gray_scene():
    # the prior acts only on colourful or dark scenes: a gray scene on a sensor unlike the typical one is untouched
    scene = _colourful()
    gray = np.repeat(scene.mean(axis=-1, keepdims=True), 3, -1)
    img = wb.cells_rgb(_mosaic(gray * 0.5, "RGGB"), "RGGB")
    got = wb.choose(img, "auto", (img, img), ticks=1000)
    assert got.method == "gray-world" and wb.angle_deg(got.illuminant, np.ones(3)) < 1e-6


def _dark_source(scene: np.ndarray, cfa: str, ticks: int = 96, dark: float = 0.004, seed: int = 3) -> ArraySource:
    """A dark capture: ``scene`` rates plus a dark rate alike in every channel (the colour filter does not see it)."""
    return _source(scene + dark, cfa, ticks=ticks, seed=seed)


@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
def test_a_dark_colourful_scene_takes_its_edges_pulled_toward_the_typical_response(cfa):
    # about 2 spikes per photosite, a fifth of them the dark rate: the mean, dark rate included, would make gray-world take the scene's yellow-green
    # for the sensor's cast
    rng = np.random.default_rng(5)
    hue = np.where(rng.random((16, 16, 1)) > 0.5, [0.5, 1.0, 0.3], [0.9, 1.0, 0.25])  # greens and yellows
    scene = np.kron(hue * (0.3 + 0.7 * rng.random((16, 16, 1))), np.ones((4, 4, 1))) * TINT * 0.04
    src = _dark_source(scene, cfa, ticks=96)
    detail: dict = {}
    a, _, why = sequence_white_balance(src, ClassicalConfig(white_balance="auto"), warn=False, detail=detail)
    assert "combined" in why and "dark scene" in why and "typical" in why and not detail["keep_balance"]
    gw = sequence_white_balance(src, ClassicalConfig(white_balance="gray-world"), warn=False)[0]
    assert wb.angle_deg(a * TINT, np.ones(3)) < 4 < 12 < wb.angle_deg(gw * TINT, np.ones(3))


@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
def test_a_dark_gray_scene_keeps_gray_world(cfa):
    # the same dark rate under a gray scene: the mean less the dark rate agrees with the edges, gray-world is kept
    # (its gains, dark rate included, keep the scene gray; the guided frame keeps that balance)
    scene = np.repeat(_coloured_edges(2).mean(axis=-1, keepdims=True), 3, -1) * TINT * 0.04
    scene[:8] = 0  # a black band: the dark rate alone
    src = _dark_source(scene, cfa, ticks=96)
    detail: dict = {}
    a, _, why = sequence_white_balance(src, ClassicalConfig(white_balance="auto"), warn=False, detail=detail)
    assert "gray-world" in why and "dark rate" in why and detail["keep_balance"]
    gw = sequence_white_balance(src, ClassicalConfig(white_balance="gray-world"), warn=False)[0]
    np.testing.assert_allclose(a, gw)


def test_dark_level_measures_the_dark_rate_where_the_scene_is_black():
    rng = np.random.default_rng(0)
    img = np.kron(rng.random((8, 8, 3)), np.ones((8, 8, 1))) * [0.3, 0.5, 0.2]
    img[:16, :16] = 0  # a black corner
    img = img + 0.004  # the dark rate
    assert abs(wb.dark_level(img) - 0.004) < 1e-9
    assert wb.dark_level(np.full((64, 64, 3), 0.2)) == pytest.approx(0.2)  # no black anywhere: its darkest patch
    assert wb.dark_level(np.zeros((0, 0, 3))) == 0.0
