"""The app's white balance (issue 26): the estimator or fixed gains R,G,B shown and editable in the Stream panel, the
picker that takes a clicked neutral patch's gains, the same recipe value the CLI's --white-balance sets, a refusal in
one sentence. Bayer (colour) and monochrome (the controls disabled with the reason)."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.io.source import ArraySource
from spikeview.session import core

GAINS = np.array([0.5, 1.0, 0.25])  # the sensor's response R, G, B to a neutral surface


def _bayer(size=64, ticks=200, seed=0):
    from spikeview.cfa import channel_map

    rng = np.random.default_rng(seed)
    scene = np.full((size, size), 0.6)
    scene[:, size // 2:] = 0.3  # a neutral scene at two levels
    rates = scene * GAINS[channel_map("RGGB", size, size)]
    return ArraySource((rng.random((ticks, size, size)) < rates).astype(np.uint8), cfa="RGGB")


def test_neutral_gains_make_the_picked_patch_neutral():
    src = _bayer()
    g = core.neutral_gains(src, 100, 16, 32)
    ratio = g / g[1]
    assert np.allclose(ratio, 1.0 / GAINS, rtol=0.08), ratio
    with pytest.raises(Exception, match="monochrome"):
        core.neutral_gains(ArraySource(np.zeros((20, 8, 8), np.uint8), cfa=None), 10, 2, 2)
    with pytest.raises(Exception, match="outside"):
        core.neutral_gains(src, 100, 99, 5)


def test_the_picker_and_the_typed_gains_set_the_recipes_white_balance(qtbot, window):
    from spikeview.session.presets import session_recipe

    window.set_stream(core.memory_stream(_bayer(), "neutral"))
    qtbot.waitUntil(lambda: window.session.stream is not None and window.session.stream.label == "neutral", timeout=60000)
    panel = window.stream_panel
    assert panel.wb.isEnabled()
    panel.wb_pick.setChecked(True)
    window.canvas.clicked.emit(16, 32)
    wb = window.session.get("white_balance")
    g = np.array([float(v) for v in wb.split(",")])
    assert np.allclose(g / g[1], 1.0 / GAINS, rtol=0.08) and not panel.wb_pick.isChecked()
    assert session_recipe(window.session).classical.white_balance == wb  # what an export and the CLI use
    panel.wb.setEditText("gray-edge")
    panel.wb.lineEdit().editingFinished.emit()
    assert window.session.get("white_balance") == "gray-edge"
    errors = []
    panel.error.connect(errors.append)
    panel.wb.setEditText("purple")
    panel.wb.lineEdit().editingFinished.emit()
    assert window.session.get("white_balance") == "gray-edge" and errors and "purple" in errors[0]


def test_a_monochrome_capture_disables_the_white_balance_with_the_reason(qtbot, window):
    rng = np.random.default_rng(1)
    window.set_stream(core.memory_stream(ArraySource((rng.random((60, 32, 32)) < 0.3).astype(np.uint8), cfa=None), "mono"))
    qtbot.waitUntil(lambda: window.session.stream is not None and window.session.stream.label == "mono", timeout=60000)
    panel = window.stream_panel
    assert not panel.wb.isEnabled() and not panel.wb_pick.isEnabled() and panel.wb.toolTip()
