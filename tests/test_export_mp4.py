"""MP4 export, read back through PyAV; slow-motion arithmetic."""

from __future__ import annotations

import tomllib
from fractions import Fraction

import av  # a required dependency: a broken install fails here, it is not skipped
import numpy as np
import pytest

from spikeview.errors import Cancelled, ParameterError
from spikeview.export import (
    ExportConfig,
    ExportMetadata,
    describe_slow_motion,
    export_frames,
    open_exporter,
    slow_motion_factor,
)
from spikeview.export.atomic import PARTIAL_MARKER
from spikeview.export.display import to_display

H, W = 32, 48
# flat test colours in linear light; saturated primaries are the hardest for 4:2:0 + BT.709
COLOURS = [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (0.5, 0.2, 0.05), (0.18, 0.18, 0.18), (0.9, 0.9, 0.9)]


def flat(colour, h=H, w=W) -> np.ndarray:
    return np.broadcast_to(np.array(colour, np.float32), (h, w, 3)).copy()


def decode(path):
    """(stream facts, list of decoded rgb24 frames, container metadata)."""
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        facts = {
            "codec": s.codec_context.name,
            "pix_fmt": s.codec_context.pix_fmt,
            "size": (s.width, s.height),
            "rate": s.average_rate,
            "colorspace": s.codec_context.colorspace,
            "color_range": s.codec_context.color_range,
        }
        decoded = [(f.time, f.to_ndarray(format="rgb24")) for f in c.decode(video=0)]
        meta = dict(c.metadata)
    return facts, decoded, meta


def stray_temporaries(folder):
    return [p.name for p in folder.iterdir() if PARTIAL_MARKER in p.name]


def test_slow_motion_factor_and_text():
    # 20 kHz, one frame per 10 ticks, 30 fps: 20000 / 300 = 66.67× (the brief's example)
    assert slow_motion_factor(20_000, 10, 30) == pytest.approx(66.6667, rel=1e-5)
    assert describe_slow_motion(slow_motion_factor(20_000, 10, 30)) == (
        "66.7× slow motion (1 s of video shows 15 ms of capture)"
    )
    # 20 kHz, one frame per 2000 ticks (0.1 s of capture), 10 fps: real time
    assert describe_slow_motion(slow_motion_factor(20_000, 2000, 10)).startswith("real time")
    # one frame per tick at 25 fps: 800×
    assert describe_slow_motion(slow_motion_factor(20_000, 1, 25)).startswith(
        "800× slow motion (1 s of video shows 1.25 ms"
    )
    assert describe_slow_motion(0.5) == "2× time-lapse (1 s of video shows 2 s of capture)"
    with pytest.raises(ParameterError, match="step_ticks"):
        slow_motion_factor(20_000, 0, 30)


def test_mp4_stream_properties_and_colours(tmp_path):
    x = [flat(c) for c in COLOURS]
    meta = ExportMetadata(
        source="cap.dat", method="tfp", window=(0, 10), centre_tick=5, step_ticks=10, params={"window_ticks": 10}
    )
    (path,) = export_frames(x, tmp_path / "v.mp4", ExportConfig(fps=30.0, crf=18), meta)
    assert path.name == "v.mp4" and [p.name for p in tmp_path.iterdir()] == ["v.mp4"]
    facts, decoded, container_meta = decode(path)
    assert facts["codec"] == "h264"
    assert facts["pix_fmt"] == "yuv420p"
    assert facts["size"] == (W, H)
    assert facts["rate"] == 30
    assert facts["colorspace"] == 1 and facts["color_range"] == 1  # BT.709, limited (MPEG) range
    assert len(decoded) == len(COLOURS)
    assert [t for t, _ in decoded] == pytest.approx([i / 30 for i in range(len(COLOURS))])
    for (_, rgb), colour in zip(decoded, COLOURS, strict=True):
        expected = to_display(flat(colour, 1, 1), ExportConfig())[0, 0].astype(int)
        # 8-bit limited-range Y'CbCr costs up to ~2 codes; crf 18 on a flat frame adds ~1
        assert np.abs(rgb.reshape(-1, 3).mean(0) - expected).max() <= 3, (colour, expected)
    assert container_meta["title"] == (
        "tfp reconstruction of cap.dat at 20000 Hz, 66.7× slow motion (1 s of video shows 15 ms of capture)"
    )
    record = tomllib.loads(container_meta["comment"])
    assert record["params"] == {"window_ticks": 10}
    assert record["slow_motion"] == pytest.approx(20_000 / 300)
    assert record["export"]["crf"] == 18


def test_mp4_fractional_fps(tmp_path):
    (path,) = export_frames([flat(COLOURS[4])] * 3, tmp_path / "ntsc.mp4", ExportConfig(fps=29.97))
    facts, decoded, _ = decode(path)
    assert facts["rate"] == Fraction(2997, 100)
    assert len(decoded) == 3


@pytest.mark.parametrize(("mode", "size"), [("pad", (48, 32)), ("crop", (46, 30))])
def test_mp4_odd_size_made_even(tmp_path, mode, size):
    x = flat((0.0, 0.0, 0.0), 31, 47)
    x[:, -1] = 1.0  # a white last column: kept (and repeated) by padding, dropped by cropping
    (path,) = export_frames([x], tmp_path / f"{mode}.mp4", ExportConfig(even_size=mode))
    facts, decoded, _ = decode(path)
    assert facts["size"] == size
    last_col = decoded[0][1][:, -1].mean()
    assert last_col > 200 if mode == "pad" else last_col < 40


def test_mp4_mono_is_grey(tmp_path):
    (path,) = export_frames([np.full((H, W), 0.5, np.float32)] * 2, tmp_path / "m.mp4")
    _, decoded, _ = decode(path)
    rgb = decoded[1][1].reshape(-1, 3).mean(0)
    assert np.abs(rgb - 188).max() <= 3  # linear 0.5 → sRGB code 188 in every channel


def test_mp4_cancel_keeps_a_valid_shorter_video(tmp_path):
    done = []
    with pytest.raises(Cancelled):
        export_frames(
            [flat(c) for c in COLOURS],
            tmp_path / "c.mp4",
            cancel=lambda: len(done) >= 3,
            progress=lambda k, n: done.append(k),
        )
    assert [p.name for p in tmp_path.iterdir()] == ["c.mp4"]
    facts, decoded, _ = decode(tmp_path / "c.mp4")
    assert facts["codec"] == "h264" and len(decoded) == 3
    expected = to_display(flat(COLOURS[2], 1, 1), ExportConfig())[0, 0].astype(int)
    assert np.abs(decoded[2][1].reshape(-1, 3).mean(0) - expected).max() <= 3


def test_mp4_cancel_before_any_frame_leaves_nothing(tmp_path):
    with pytest.raises(Cancelled):
        export_frames([flat(c) for c in COLOURS], tmp_path / "c.mp4", cancel=lambda: True)
    assert list(tmp_path.iterdir()) == []


def test_mp4_error_mid_export_leaves_nothing(tmp_path):
    (tmp_path / "v.mp4").write_bytes(b"previous video")
    with pytest.raises(ZeroDivisionError):
        with open_exporter(tmp_path / "v.mp4", 4, (H, W, 3), overwrite=True) as ex:
            ex.write(flat(COLOURS[0]))
            ex.write(flat(COLOURS[1]))
            1 / 0  # noqa: B018 - the failure under test
    assert stray_temporaries(tmp_path) == []
    assert (tmp_path / "v.mp4").read_bytes() == b"previous video"


def test_mp4_name_takes_no_pattern(tmp_path):
    with pytest.raises(ParameterError, match="no frame-number field"):
        open_exporter(tmp_path / "v_%04d.mp4", 2, (H, W, 3))
