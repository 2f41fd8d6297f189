"""PNG sequences, read back through OpenImageIO."""

from __future__ import annotations

import tomllib

import numpy as np
import OpenImageIO as oiio  # a required dependency: a broken install fails here, it is not skipped
import pytest

from spikeview.errors import ParameterError
from spikeview.export import ExportConfig, ExportMetadata, export_frames, read_export_metadata
from spikeview.export.atomic import PARTIAL_MARKER
from spikeview.export.display import srgb_encode

H, W = 32, 48

# Linear inputs and their 8-bit sRGB codes, from the IEC 61966-2-1 curve
# (1.055·v^(1/2.4) − 0.055 above 0.0031308, 12.92·v below), rounded to nearest:
#   0.5 → 0.73536·255 = 187.52 → 188;  0.1 → 0.34919·255 = 89.04 → 89;
#   0.0031308 → 0.04045·255 = 10.31 → 10;  0.001 → 0.01292·255 = 3.29 → 3.
SRGB8 = [(0.0, 0), (0.001, 3), (0.0031308, 10), (0.1, 89), (0.5, 188), (1.0, 255)]


def ramp_frame(values, mono=False) -> np.ndarray:
    """A frame whose column j holds values[j % len(values)] (all channels)."""
    row = np.array([values[j % len(values)] for j in range(W)], np.float32)
    frame = np.broadcast_to(row, (H, W)).copy()
    return frame if mono else np.repeat(frame[:, :, None], 3, axis=2)


def read(path, fmt="uint8"):
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    try:
        spec = inp.spec()
        attrs = {a.name: a.value for a in spec.extra_attribs}
        pixels = inp.read_image(fmt)
    finally:
        inp.close()
    return spec, attrs, pixels


def test_srgb_curve_reference_values():
    lin = np.array([v for v, _ in SRGB8], np.float32)
    codes = np.rint(srgb_encode(lin) * 255).astype(int)
    assert codes.tolist() == [c for _, c in SRGB8]


def test_png_8bit_srgb_values_size_and_metadata(tmp_path):
    x = ramp_frame([v for v, _ in SRGB8])
    meta = ExportMetadata(source="caps/é.dat", method="guided", window=(0, 10), centre_tick=5, params={"steps": 50})
    written = export_frames([x, x], tmp_path / "f_%04d.png", metadata=meta)
    assert [p.name for p in written] == ["f_0000.png", "f_0001.png"]
    spec, attrs, pixels = read(written[0])
    assert (spec.width, spec.height, spec.nchannels) == (W, H, 3)
    assert spec.format == oiio.TypeDesc("uint8")
    expected = [c for _, c in SRGB8]
    assert pixels[3, : len(expected), 0].tolist() == expected
    assert (pixels[..., 0] == pixels[..., 2]).all()
    # text chunks: numbers as text, the full TOML record in spikeview:config
    assert attrs["spikeview:source"] == "caps/é.dat"
    assert attrs["spikeview:method"] == "guided"
    assert attrs["spikeview:tickStart"] == "0" and attrs["spikeview:tickStop"] == "10"
    assert attrs["spikeview:centreTick"] == "5"
    assert float(attrs["spikeview:tickRate"]) == 20_000.0
    record = tomllib.loads(attrs["spikeview:config"])
    assert record["params"] == {"steps": 50} and record["format"] == "png"
    assert read_export_metadata(written[1])["frame_index"] == 1
    assert "srgb" in attrs["oiio:ColorSpace"].lower()


def test_png_16bit(tmp_path):
    x = ramp_frame([0.0, 0.5, 1.0])
    (path,) = export_frames([x], tmp_path / "deep.png", ExportConfig(png_bits=16))
    spec, _, pixels = read(path, "uint16")
    assert spec.format == oiio.TypeDesc("uint16")
    # 0.5 → 0.735357 (sRGB) · 65535 = 48191.62 → 48192
    assert pixels[0, :3, 1].tolist() == [0, 48192, 65535]


def test_png_fixed_levels_no_auto_levels(tmp_path):
    dim = ramp_frame([0.0, 0.1])  # a dim frame stays dim: nothing is stretched to full range
    (path,) = export_frames([dim], tmp_path / "dim.png")
    assert read(path)[2][0, :2, 0].tolist() == [0, 89]
    # black 0.25, white 0.75: 0.2 → clipped to 0, 0.5 → 0.5 → 188, 0.9 → clipped to 255
    levels = ramp_frame([0.2, 0.5, 0.9])
    (path,) = export_frames([levels], tmp_path / "lv.png", ExportConfig(black=0.25, white=0.75))
    assert read(path)[2][0, :3, 0].tolist() == [0, 188, 255]


def test_png_gamma_and_linear_transfer(tmp_path):
    x = ramp_frame([0.5])
    (g,) = export_frames([x], tmp_path / "g.png", ExportConfig(transfer="gamma", gamma=2.2))
    (lin,) = export_frames([x], tmp_path / "l.png", ExportConfig(transfer="linear"))
    assert read(g)[2][0, 0, 0] == 186  # 0.5^(1/2.2) = 0.72974 · 255 = 186.08
    assert read(lin)[2][0, 0, 0] == 128  # 0.5 · 255 = 127.5 → 128 (round half to even of 127.5 is 128)


def test_png_mono_is_greyscale(tmp_path):
    x = ramp_frame([0.0, 0.5], mono=True)
    (path,) = export_frames([x], tmp_path / "mono.png")
    spec, _, pixels = read(path)
    assert spec.nchannels == 1
    assert pixels[0, :2, 0].tolist() == [0, 188]


def test_png_multi_frame_needs_a_pattern(tmp_path):
    with pytest.raises(ParameterError, match=r"out_%04d\.png"):
        export_frames([ramp_frame([0.5])] * 2, tmp_path / "out.png")
    assert list(tmp_path.iterdir()) == []


def test_png_error_mid_export_keeps_finished_frames(tmp_path):
    def gen():
        yield ramp_frame([0.5])
        raise KeyError("reconstruction failed")

    with pytest.raises(KeyError):
        export_frames(gen(), tmp_path / "p_%d.png", n_frames=3)
    assert [p.name for p in tmp_path.iterdir()] == ["p_0.png"]
    assert not any(PARTIAL_MARKER in p.name for p in tmp_path.iterdir())
