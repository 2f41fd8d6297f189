"""spikeview.pipeline: the one path from a recipe and a source to frames and files (monochrome and Bayer)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from spikeview.classical.reconstruct import reconstruct_frames
from spikeview.errors import Cancelled, ParameterError
from spikeview.io import ArraySource
from spikeview.pipeline import (
    SequenceState,
    WriteOptions,
    exposure_mapping,
    output_white,
    parse_range,
    prepare_sequence,
    reconstruct_windows,
    recipe_for_state,
    window_centres,
    write_sequence,
)
from spikeview.recipe import Recipe

T, H, W = 200, 24, 32
CFAS = ("RGGB", None)


def _source(cfa: str | None) -> ArraySource:
    """Rates that differ per channel (a colour cast to estimate) and across the frame (texture)."""
    rng = np.random.default_rng(5)
    rate = np.tile(np.linspace(0.1, 0.6, W, dtype=np.float32), (H, 1))
    if cfa is not None:
        rate[0::2, 0::2] *= 0.5  # the red sites of RGGB fire less: α_R > α_G
    return ArraySource(rng.random((T, H, W)) < rate, cfa=cfa)


def _recipe(method: str = "tfp", **values) -> Recipe:
    return Recipe().with_values({"run.method": method, **values})


def test_window_centres_at_range_and_default():
    assert window_centres(_recipe(**{"run.at": 50}), T) == ([50], 10)
    assert window_centres(_recipe(**{"run.range": "0:100:25"}), T) == ([0, 25, 50, 75], 25)
    assert window_centres(_recipe(**{"run.range": "150:400"}), T) == ([150, 160, 170, 180, 190], 10)  # clipped to the stream
    assert window_centres(_recipe(), T) == ([T // 2], 10)
    assert window_centres(_recipe("tfi"), T)[1] == 2 * Recipe().classical.tfi_half_window  # TFI spans two half-windows
    with pytest.raises(ParameterError, match="--at 200 is outside"):
        window_centres(_recipe(**{"run.at": T}), T)


@pytest.mark.parametrize("text", ["5", "a:b", "10:5", "0:10:0"])
def test_parse_range_refuses_what_it_cannot_read(text):
    with pytest.raises(ParameterError, match="--range"):
        parse_range(text, 10)


@pytest.mark.parametrize("cfa", CFAS)
def test_prepare_sequence_alpha_once_and_only_for_bayer(cfa):
    src = _source(cfa)
    state = prepare_sequence(src, _recipe())
    assert state.white is not None and state.white > 0
    if cfa is None:
        assert state.alpha is None
    else:
        assert state.alpha.shape == (3,) and state.alpha[0] > state.alpha[1]  # the weak red channel is lifted
        fixed = prepare_sequence(src, _recipe(**{"classical.alpha": [1.0, 2.0, 3.0]}))
        assert fixed.alpha.tolist() == [1.0, 2.0, 3.0]
        assert prepare_sequence(src, _recipe(**{"classical.colour_cast": False})).alpha is None


@pytest.mark.parametrize("cfa", CFAS)
def test_recipe_for_state_records_what_the_sequence_decided(cfa):
    src = _source(cfa)
    recipe = _recipe()
    state = prepare_sequence(src, recipe)
    recorded = recipe_for_state(recipe, state)
    assert recorded.export.white == pytest.approx(state.white)
    assert (recorded.classical.alpha is None) == (cfa is None)
    # a recorded recipe prepares the same state again: a saved preset re-runs to the same pixels
    again = prepare_sequence(src, recorded)
    assert again.white == pytest.approx(state.white) and (again.alpha is None) == (state.alpha is None)


def test_output_white_set_over_estimate_over_one():
    assert output_white(_recipe(**{"export.white": 0.5}), SequenceState(None, 2.0)) == 0.5
    assert output_white(_recipe(), SequenceState(None, 2.0)) == 2.0
    assert output_white(_recipe(), SequenceState(None, None)) == 1.0


def test_exposure_mapping_clips_npy_and_keeps_exr_linear(tmp_path):
    state = SequenceState(None, 2.0)
    frame = np.array([[0.5, 4.0]], dtype=np.float32)
    _, npy = exposure_mapping(_recipe(), state, tmp_path / "a.npy")
    cfg, exr = exposure_mapping(_recipe(), state, tmp_path / "a.exr")
    assert npy(frame).tolist() == [[0.25, 1.0]] and exr(frame).tolist() == [[0.25, 2.0]]
    assert cfg.white == 1.0  # frames arrive divided by the white point


@pytest.mark.parametrize("cfa", CFAS)
def test_reconstruct_windows_is_the_classical_path_with_the_sequence_alpha(cfa):
    src = _source(cfa)
    recipe = _recipe()
    state = prepare_sequence(src, recipe)
    got = list(reconstruct_windows(src, [40, 120], recipe, state))
    want = list(reconstruct_frames(src, [40, 120], recipe.classical.replace(method="tfp"), alpha=state.alpha))
    assert len(got) == 2 and all(np.array_equal(g, w) for g, w in zip(got, want))
    assert got[0].shape == ((H, W, 3) if cfa else (H, W))


@pytest.mark.parametrize("cfa", CFAS)
def test_reconstruct_windows_crops_the_roi_on_the_cfa_phase(cfa):
    src = _source(cfa)
    full = next(reconstruct_windows(src, [100], _recipe()))
    part = next(reconstruct_windows(src, [100], _recipe(), roi=(5, 3, 10, 8)))  # origin rounded down to (4, 2)
    assert np.array_equal(part, full[2:11, 4:15])


def test_reconstruct_windows_stops_when_cancelled():
    flag = threading.Event()
    flag.set()
    with pytest.raises(Cancelled):
        list(reconstruct_windows(_source("RGGB"), [40, 80], _recipe(), cancel=flag))


@pytest.mark.parametrize("cfa", CFAS)
def test_write_sequence_writes_the_exposed_frames(tmp_path, cfa):
    src = _source(cfa)
    recipe = _recipe()
    state = prepare_sequence(src, recipe)
    out = tmp_path / "f.npy"
    write_sequence(src, recipe, [40, 80, 120], out, WriteOptions(state=state))
    _, expose = exposure_mapping(recipe, state, out)
    want = np.stack([expose(f) for f in reconstruct_windows(src, [40, 80, 120], recipe, state)])
    got = np.load(out)
    assert got.shape == want.shape and np.array_equal(got, want)


def test_a_channel_without_spikes_is_said_once_as_a_warning_or_a_note():
    from spikeview.classical.colour_cast import ColourCastWarning

    rng = np.random.default_rng(2)
    spikes = rng.random((T, H, W)) < 0.3
    spikes[:, 0::2, 0::2] = False  # the red sites of RGGB never fire
    src = ArraySource(spikes, cfa="RGGB")
    with pytest.warns(ColourCastWarning, match="R"):
        loud = prepare_sequence(src, _recipe())
    quiet = prepare_sequence(src, _recipe(), warn=False)  # the app's worker: the sentence, no warning
    assert quiet.note == loud.note and "R" in quiet.note
    assert np.array_equal(quiet.alpha, loud.alpha) and quiet.white == loud.white
    assert prepare_sequence(_source("RGGB"), _recipe()).note is None
