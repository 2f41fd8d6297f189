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
    # the gains the sequence got are shown beside the choice, the CLI's whole line (which, why) as their tooltip
    qtbot.waitUntil(lambda: panel.wb_gains.text() != "", timeout=60000)
    r, _, b = (float(v) for v in panel.wb_gains.text().split(" : "))
    assert np.allclose([r, b], [GAINS[1] / GAINS[0], GAINS[1] / GAINS[2]], rtol=0.1), panel.wb_gains.text()
    assert panel.wb_gains.toolTip().startswith("white balance auto → gray-world") and "gains R" in panel.wb.toolTip()
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
    qtbot.waitUntil(lambda: window.controller.capture_white is not None, timeout=60000)  # the sequence's estimate
    assert not panel.wb.isEnabled() and not panel.wb_pick.isEnabled() and "monochrome" in panel.wb.toolTip().lower()
    assert panel.wb_gains.text() == ""


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_a_camera_profile_chosen_in_stream_settings_corrects_and_is_recorded(qtbot, window, tmp_path, cfa):
    """Stream settings ▸ Camera profile (``--camera`` in the CLI): the profile is attached, auto white balance takes
    its colour response (Bayer), the preset records it and gives the CLI's pixels; a profile of another geometry is
    refused in the dialog in one sentence and the stream stays as it was."""
    from spikeview.cli.main import main
    from spikeview.session.presets import save_preset
    from spikeview.sim import SimConfig, simulate_to_file
    from spikeview.sim.scenes import StaticScene

    def cfg(ticks):
        return SimConfig(n_ticks=ticks, seed=5, cfa=cfa, spectral_gains=(0.55, 1.0, 0.45), hot_pixels=0.01, gt_every=5)

    n = 32
    for name, value, ticks in (("dark", 0.0, 1500), ("flat", 0.8, 800)):
        simulate_to_file(StaticScene(np.full((n, n, 3), value, np.float32), srgb=False), cfg(ticks), tmp_path / f"{name}.dat")
    rng = np.random.default_rng(3)
    img = np.kron(rng.random((8, 8, 3)), np.ones((4, 4, 1))).astype(np.float32)
    simulate_to_file(StaticScene(img, srgb=False), cfg(80), tmp_path / "cap.dat")
    simulate_to_file(StaticScene(np.zeros((n, n + 8, 3), np.float32), srgb=False), cfg(20), tmp_path / "wide.dat")
    prof, wide = tmp_path / "cam.toml", tmp_path / "wide.toml"
    assert main(["calibrate", "--dark", str(tmp_path / "dark.dat"), "--flat", str(tmp_path / "flat.dat"), "--out", str(prof)]) == 0
    assert main(["calibrate", "--dark", str(tmp_path / "wide.dat"), "--out", str(wide)]) == 0

    window.set_stream(core.open_file(tmp_path / "cap.dat"))
    s = window.session
    qtbot.waitUntil(lambda: s.stream is not None and s.stream.label == "cap.dat", timeout=60000)
    assert getattr(s.source.info.camera, "path", None) is None  # no profile: the capture's own hot pixels at most
    qtbot.waitUntil(lambda: window.controller.capture_white is not None, timeout=60000)
    white0 = window.controller.capture_white
    dlg = window.stream_settings()
    assert dlg.camera.text() == ""
    dlg.camera.setText(str(wide))
    dlg.update_preview()
    ok = dlg.buttons.button(dlg.buttons.StandardButton.Ok)
    assert not ok.isEnabled() and "wide.toml" in dlg.error.text() and "\n" not in dlg.error.text().strip()
    dlg.camera.setText(str(prof))
    dlg.update_preview()
    assert ok.isEnabled() and dlg.error.text() == ""
    dlg.accept()
    qtbot.waitUntil(lambda: getattr(s.source.info.camera, "path", None) is not None, timeout=60000)
    assert s.source.info.camera.path.resolve() == prof.resolve()
    # the exposure is re-estimated on the corrected rates, as the CLI estimates it
    qtbot.waitUntil(lambda: window.controller.capture_white != white0
                    and s.get("white") == window.controller.capture_white, timeout=60000)
    s.set_tick(40)
    preset = tmp_path / "app.preset.toml"
    save_preset(s, preset)
    from spikeview.recipe import Recipe

    assert Recipe.load(preset).stream.camera == str(prof.absolute())
    assert main(["reconstruct", str(tmp_path / "cap.dat"), "--preset", str(preset), "--out", str(tmp_path / "a.npy")]) == 0
    assert main(["reconstruct", str(tmp_path / "cap.dat"), "--camera", str(prof), "--at", "40",
                 "--out", str(tmp_path / "b.npy")]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy"))
    if cfa != "none":
        from spikeview.classical.colour_cast import sequence_white_balance

        _, _, why = sequence_white_balance(s.source, Recipe.load(preset).classical, warn=False)
        assert "auto → profile" in why
    dlg = window.stream_settings()  # the dialog shows the attached profile; clearing it detaches it
    assert dlg.camera.text() == str(prof.absolute())
    dlg.camera.setText("")
    dlg.update_preview()
    dlg.accept()
    qtbot.waitUntil(lambda: getattr(s.source.info.camera, "path", None) is None, timeout=60000)
