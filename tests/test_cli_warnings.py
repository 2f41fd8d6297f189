"""A warning reaches a CLI user as one line like the CLI's other messages, without a source path or code line
(here the colour cast of a Bayer capture whose blue photosites never fire; the same formatting serves
OpenVINO giving up mid-run)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np


def test_a_warning_is_one_plain_line(tmp_path):
    from spikeview.io.plain import write_plain

    rng = np.random.default_rng(0)
    s = (rng.random((60, 16, 16)) < 0.3).astype(np.uint8)
    s[:, 1::2, 1::2] = 0  # RGGB: the blue photosites never fire
    write_plain(tmp_path / "noblue.dat", s, cfa="RGGB")
    r = subprocess.run([sys.executable, "-m", "spikeview", "reconstruct", str(tmp_path / "noblue.dat"), "--method", "tfp",
                        "--at", "30", "--out", str(tmp_path / "nb.png")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "channel B has no spikes" in ln]
    assert len(lines) == 1 and lines[0].startswith("spikeview: warning: Colour cast:"), r.stderr
    assert ".py:" not in r.stderr and "Warning:" not in r.stderr and "warnings.warn" not in r.stderr


def test_a_dark_capture_tells_a_tfp_user_what_to_do(tmp_path):
    """A capture whose 10-tick windows hold under 3 spikes at the white (its white point came from longer windows):
    TFP's frame is single spikes, and the CLI says so with the two ways out; a bright capture gets no such note; the
    guided method none either. Monochrome and Bayer."""
    from spikeview.io.plain import write_plain

    rng = np.random.default_rng(1)
    for cfa in ("RGGB", "none"):
        for name, p in (("dark", 0.02), ("bright", 0.4)):
            s = (rng.random((200, 32, 32)) < p * np.linspace(0.2, 1.0, 32)[None, None, :]).astype(np.uint8)
            path = tmp_path / f"{name}_{cfa}.dat"
            write_plain(path, s, cfa=None if cfa == "none" else cfa)
            for method in ("tfp", "guided") if name == "dark" else ("tfp",):
                r = subprocess.run([sys.executable, "-m", "spikeview", "reconstruct", str(path), "--cfa", cfa,
                                    "--width", "32", "--height", "32", "--method", method, "--at", "100",
                                    "--out", str(tmp_path / f"{name}_{cfa}_{method}.png")],
                                   capture_output=True, text=True, timeout=300)
                assert r.returncode == 0, r.stderr
                said = "note: a dark capture for a 10-tick window" in r.stderr and "--method guided" in r.stderr
                assert said == (name == "dark" and method == "tfp"), (name, cfa, method, r.stderr)


def test_a_dark_captures_tfi_searches_as_far_as_its_intervals_need(tmp_path):
    """TFI on a dark capture: the ±32-tick default search capped most intervals and showed a flat level; the search
    now reaches until an empty search reads the capture's darkest floor (spikeview.pipeline.tfi_reach), said in one
    note, and the frame is TFI at that reach. A bright capture keeps its setting and gets no note. Mono and Bayer."""
    import pytest

    from spikeview.classical.defects import find_defects
    from spikeview.classical.tfi import tfi
    from spikeview.io import open_source
    from spikeview.io.plain import write_plain
    from spikeview.pipeline import prepare_sequence, reconstruct_windows, tfi_half_window
    from spikeview.recipe import Recipe

    rng = np.random.default_rng(2)
    for cfa in ("RGGB", "none"):
        for name, p in (("dark", 0.03), ("bright", 0.4)):
            ramp = p * np.linspace(0.1, 1.0, 32)[None, None, :]
            v = rng.random((32, 32))
            s = np.zeros((400, 32, 32), np.uint8)
            for t in range(400):  # integrate-and-fire: evenly spaced spikes, as a real pixel's
                v += ramp[0]
                s[t] = v >= 1
                v -= s[t]
            path = tmp_path / f"{name}_{cfa}.dat"
            write_plain(path, s, cfa=None if cfa == "none" else cfa)
            r = subprocess.run([sys.executable, "-m", "spikeview", "reconstruct", str(path), "--cfa", cfa, "--width", "32",
                                "--height", "32", "--method", "tfi", "--at", "200", "--out", str(tmp_path / f"{name}.npy"),
                                "--overwrite"], capture_output=True, text=True, timeout=300)
            assert r.returncode == 0, r.stderr
            said = "note: a dark capture, so TFI searches ±" in r.stderr and "not ±32 (--tfi-half-window)" in r.stderr
            assert said == (name == "dark"), (name, cfa, r.stderr)
            recipe = Recipe().with_values({"run.method": "tfi", "run.at": 200})
            with open_source(path, width=32, height=32, cfa=cfa) as src:
                state = prepare_sequence(src, recipe, warn=False)
                hw = tfi_half_window(32, state)
                frame = next(reconstruct_windows(src, [200], recipe, state))
                raw = tfi(src, 200, hw)
                if name == "bright":
                    assert state.tfi_reach is None and hw == 32
                    continue
                assert f"±{hw} ticks" in r.stderr and 40 <= hw <= 512 and hw == state.tfi_reach
                assert tfi_half_window(1, state) == hw and tfi_half_window(512, state) == 512  # at least the setting
                # an empty search reads 1/(2·half_window): the capture's darkest floor now, not a level near the white
                floor = find_defects(src).floor
                assert 1 / (2 * hw) == pytest.approx(floor, rel=0.05)
                # photosites firing at least once in half_window ticks are never capped now; with ±32 many of them were
                seen = np.s_[:, ramp[0, 0] >= 1.0 / hw]
                assert (raw[seen] == np.float32(1 / (2 * hw))).mean() == 0
                assert (tfi(src, 200, 32)[seen] == np.float32(1 / 64)).mean() > 0.2
                # the frame is TFI at that reach (the colour cast and demosaic applied to it as before)
                ref = next(reconstruct_windows(src, [200], recipe.with_values({"classical.tfi_half_window": hw}),
                                               prepare_sequence(src, recipe, warn=False)))
                assert np.array_equal(frame, ref)
