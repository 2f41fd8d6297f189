"""Scenes: image sequences, videos, synthetic motion, colour conversion, bad inputs, the demo."""

import numpy as np
import pytest

from spikeview.errors import InputFileError, ParameterError
from spikeview.sim.config import SimConfig
from spikeview.sim.demo import demo_capture, demo_scene
from spikeview.sim.images import linear_to_srgb, list_image_files, read_image, srgb_to_linear, to_linear_rgb
from spikeview.sim.scenes import (
    ArrayScene,
    Fan,
    ImageSequenceScene,
    MotionScene,
    ResizedScene,
    StaticScene,
    VideoScene,
    open_scene,
)
from spikeview.sim.simulator import simulate

# the largest slope of the sRGB decoding curve (at 1.0): 2.4/1.055 · 1 = 2.275 linear per unit
SRGB_MAX_SLOPE = 2.4 / 1.055


def _write_image(path, pixels):
    import OpenImageIO as oiio

    pixels = np.ascontiguousarray(pixels)
    fmt = {np.dtype(np.uint8): "uint8", np.dtype(np.uint16): "uint16", np.dtype(np.float32): "float"}[pixels.dtype]
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt))
    out.write_image(pixels)
    out.close()


def _write_video(path, colours, size=32, fps=25):
    import av

    with av.open(str(path), "w") as c:
        s = c.add_stream("mpeg4", rate=fps)
        s.width = s.height = size
        s.pix_fmt = "yuv420p"
        s.options = {"qscale": "1"}
        for col in colours:
            frame = av.VideoFrame.from_ndarray(np.full((size, size, 3), col, np.uint8), format="rgb24")
            for p in s.encode(frame):
                c.mux(p)
        for p in s.encode():
            c.mux(p)


# ------------------------------------------------------------------------------- colour
def test_srgb_conversion():
    # IEC 61966-2-1 reference points: 0.5 → 0.21404, 0.04045 → 0.0031308 (the linear knee)
    assert srgb_to_linear(np.float32(0.5)) == pytest.approx(0.2140411, abs=1e-6)
    assert srgb_to_linear(np.float32(0.04045)) == pytest.approx(0.0031308, abs=1e-6)
    x = np.linspace(0, 1, 101, dtype=np.float32)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=2e-6)
    # uint8 goes through the sRGB curve, floats are taken as linear
    assert to_linear_rgb(np.full((1, 1, 3), 128, np.uint8))[0, 0, 0] == pytest.approx(0.2158605, abs=1e-6)
    assert to_linear_rgb(np.full((1, 1, 3), 0.5, np.float32))[0, 0, 0] == 0.5
    # grey images become three equal channels
    assert to_linear_rgb(np.zeros((4, 5), np.uint16)).shape == (4, 5, 3)


def test_read_image_decodes_integer_files_as_srgb_and_float_files_as_linear(tmp_path):
    rng = np.random.default_rng(0)
    px = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    _write_image(tmp_path / "a.png", px)
    _write_image(tmp_path / "a16.png", px.astype(np.uint16) * 257)
    _write_image(tmp_path / "a.exr", px.astype(np.float32) / 255)
    ref = srgb_to_linear(px.astype(np.float32) / 255)
    np.testing.assert_allclose(read_image(tmp_path / "a.png"), ref, atol=1e-6)
    np.testing.assert_allclose(read_image(tmp_path / "a16.png"), ref, atol=1e-6)
    np.testing.assert_allclose(read_image(tmp_path / "a.exr"), px / 255.0, atol=1e-6)


# ------------------------------------------------------------------------------- image sequences
def test_image_sequence_blends_linearly_between_frames_in_natural_order(tmp_path):
    levels = {"frame2.png": 40, "frame10.png": 200, "frame1.png": 120}
    for name, v in levels.items():
        _write_image(tmp_path / name, np.full((6, 8, 3), v, np.uint8))
    scene = ImageSequenceScene(tmp_path, fps=10.0)
    assert [f.name for f in scene.files] == ["frame1.png", "frame2.png", "frame10.png"]
    assert scene.duration_s == pytest.approx(0.3)
    lin = {v: srgb_to_linear(np.float32(v / 255)) for v in levels.values()}
    assert scene.frame_at(0.0)[0, 0, 0] == pytest.approx(lin[120], abs=1e-6)
    # a quarter of the way from frame 1 to frame 2, blended in linear light
    assert scene.frame_at(0.125)[0, 0, 0] == pytest.approx(0.75 * lin[40] + 0.25 * lin[200], abs=1e-6)
    # the last frame is held until the end
    assert scene.frame_at(0.3)[0, 0, 0] == pytest.approx(lin[200], abs=1e-6)
    with pytest.raises(ParameterError, match="outside the scene"):
        scene.frame_at(0.31)
    # a glob pattern and an explicit list give the same files
    assert list_image_files(str(tmp_path / "frame*.png")) == scene.files
    assert ImageSequenceScene([tmp_path / "frame10.png", tmp_path / "frame1.png"], fps=5).files[0].name == "frame10.png"


def test_image_sequence_errors(tmp_path):
    with pytest.raises(InputFileError, match="no such folder"):
        ImageSequenceScene(tmp_path / "missing", fps=10)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("x")
    with pytest.raises(InputFileError, match="no image files"):
        ImageSequenceScene(empty, fps=10)
    with pytest.raises(InputFileError, match="no file matches"):
        ImageSequenceScene(str(tmp_path / "*.png"), fps=10)
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    _write_image(mixed / "a1.png", np.zeros((6, 8, 3), np.uint8))
    _write_image(mixed / "a2.png", np.zeros((6, 9, 3), np.uint8))
    with pytest.raises(InputFileError, match=r"a2\.png.*same size"):
        ImageSequenceScene(mixed, fps=10)
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "a1.png").write_bytes(b"not a png")
    with pytest.raises(InputFileError, match="not a readable image"):
        ImageSequenceScene(bad, fps=10)
    with pytest.raises(InputFileError, match="not found"):
        ImageSequenceScene([tmp_path / "nope.png"], fps=10)
    with pytest.raises(ParameterError, match="frame rate"):
        open_scene(mixed)


def test_simulating_an_image_sequence(tmp_path):
    for i, v in enumerate((0, 255)):
        _write_image(tmp_path / f"f{i}.png", np.full((8, 8, 3), v, np.uint8))
    scene = ImageSequenceScene(tmp_path, fps=100.0)  # 2 frames = 20 ms = 400 ticks
    cap = simulate(scene, SimConfig.noiseless(n_ticks=400, cfa="none", rate=1.0))
    # intensity ramps 0 → 1 over the first 200 ticks (linear blend), then holds: the total
    # charge is Σ_t I(t) = 199·200/2/200 + 200 = 299.5 ticks' worth; counts are within one spike
    assert np.abs(cap.count(0, 400).astype(np.float64) - 299.5).max() < 1.0 + 1e-6


# ------------------------------------------------------------------------------- videos
def test_video_frames_rate_blend_and_rewind(tmp_path):
    colours = [(30, 225, 90), (80, 175, 240), (130, 125, 134), (180, 75, 28), (230, 25, 178), (250, 5, 238)]
    path = tmp_path / "clip.mp4"
    _write_video(path, colours)
    scene = VideoScene(path)
    assert (scene.height, scene.width, scene.n_frames, scene.fps) == (32, 32, 6, 25.0)
    frames = [scene.frame_at(i / 25) for i in range(6)]
    for f, col in zip(frames, colours):
        # mpeg4 at qscale 1 plus the YUV 4:2:0 round trip keep uniform colours within 4/255 in
        # sRGB, i.e. 4/255 · 2.275 in linear light at worst
        np.testing.assert_allclose(f.mean(axis=(0, 1)), srgb_to_linear(np.array(col) / 255), atol=4 / 255 * SRGB_MAX_SLOPE)
    # halfway between frames 2 and 3 is the average of the decoded frames (blended in linear light)
    np.testing.assert_allclose(scene.frame_at(2.5 / 25), 0.5 * frames[2] + 0.5 * frames[3], atol=1e-6)
    # going back re-opens the file and decodes the same frame
    scene._cache.clear()
    np.testing.assert_array_equal(scene.frame_at(1 / 25), frames[1])
    scene.close()
    # the simulator refuses to run past the end of the clip (6 frames = 0.24 s = 4800 ticks)
    with pytest.raises(ParameterError, match="n_ticks"):
        simulate(VideoScene(path), SimConfig(n_ticks=5000))
    cap = simulate(open_scene(path), SimConfig(n_ticks=50, width=16, height=16))
    assert cap.gt_at(0).shape == (16, 16, 3)
    cap.close()


def test_video_errors(tmp_path):
    with pytest.raises(InputFileError, match="not found"):
        VideoScene(tmp_path / "missing.mp4")
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"\x00" * 1000)
    with pytest.raises(InputFileError, match="not a readable video"):
        VideoScene(bad)
    with pytest.raises(InputFileError, match="no such file"):
        open_scene(tmp_path / "nothing.mkv")


# ------------------------------------------------------------------------------- other scenes
def test_array_static_and_resized_scenes():
    rng = np.random.default_rng(1)
    frames = rng.uniform(0, 1, (3, 10, 12, 3)).astype(np.float32)
    scene = ArrayScene(frames, fps=50)
    np.testing.assert_array_equal(scene.frame_at(0.02), frames[1])
    np.testing.assert_allclose(scene.frame_at(0.03), 0.5 * frames[1] + 0.5 * frames[2], atol=1e-7)
    static = StaticScene(frames[0])
    assert static.duration_s is None
    np.testing.assert_array_equal(static.frame_at(123.0), frames[0])
    crop = ResizedScene(scene, crop=(1, 2, 4, 6))
    np.testing.assert_array_equal(crop.frame_at(0.02), frames[1][1:5, 2:8])
    half = ResizedScene(ArrayScene(frames, fps=50), size=(5, 6))
    assert half.frame_at(0.0).shape == (5, 6, 3)
    # a 2× shrink with anti-aliasing keeps the mean
    assert half.frame_at(0.0).mean() == pytest.approx(frames[0].mean(), abs=0.02)
    with pytest.raises(ParameterError, match="does not fit"):
        ResizedScene(scene, crop=(0, 0, 11, 12))
    with pytest.raises(ParameterError, match="positive"):
        ArrayScene(frames, fps=0)


def test_motion_scene_zoom_and_rotation_keep_the_centre_fixed():
    rng = np.random.default_rng(2)
    img = rng.uniform(0, 1, (33, 33, 3)).astype(np.float32)
    scene = MotionScene(img, zoom=2.0, rotation=90.0, scale=1.0)
    # the output centre (16, 16) shows the image centre at every time
    for t in (0.0, 0.3, 1.0):
        np.testing.assert_allclose(scene.frame_at(t)[16, 16], img[16, 16], atol=1e-5)
    # after 1 s: content turned 90° clockwise and grown 2×: the pixel 4 px right of the centre
    # shows what was 2 px above it (y down: clockwise maps "up" to "right")
    np.testing.assert_allclose(scene.frame_at(1.0)[16, 20], img[14, 16], atol=1e-5)
    with pytest.raises(ParameterError, match="zoom"):
        MotionScene(img, zoom=0.0)


def test_fan_defaults_to_the_frame_centre():
    grey = np.full((40, 60, 3), 0.5, np.float32)
    frame = MotionScene(grey, fans=[Fan(rev_per_s=2.0)], scale=1.0).frame_at(0.0)
    assert Fan().geometry(40, 60) == (29.5, 19.5, 12.0)
    # the hub region changed, the corners did not
    assert np.abs(frame[20, 30] - 0.5).max() > 0.05 or np.abs(frame[16, 36] - 0.5).max() > 0.05
    np.testing.assert_array_equal(frame[:5, :5], grey[:5, :5])
    with pytest.raises(ParameterError, match="Fan"):
        Fan(radius=-1.0)


def test_motion_scene_key_frames_at_a_render_rate_blend_in_between():
    img = np.random.default_rng(3).uniform(0, 1, (20, 20, 3)).astype(np.float32)
    exact = MotionScene(img, pan=(30.0, 0.0), scale=1.0)
    keyed = MotionScene(img, pan=(30.0, 0.0), scale=1.0, render_rate=1000.0)
    np.testing.assert_array_equal(keyed.frame_at(0.002), exact.frame_at(0.002))
    np.testing.assert_allclose(keyed.frame_at(0.0025), 0.5 * exact.frame_at(0.002) + 0.5 * exact.frame_at(0.003), atol=1e-6)


# ------------------------------------------------------------------------------- demo
def test_demo_scene_is_colourful_moving_and_deterministic():
    scene = demo_scene(64, seed=0)
    f0 = scene.frame_at(0.0)
    assert f0.shape == (64, 64, 3) and f0.dtype == np.float32
    assert 0.0 <= f0.min() and f0.max() <= 1.0
    # colourful: the per-pixel channel spread (max − min over R, G, B) is large somewhere
    assert np.percentile(f0.max(axis=2) - f0.min(axis=2), 90) > 0.2
    assert np.abs(scene.frame_at(0.05) - f0).mean() > 0.005
    np.testing.assert_array_equal(demo_scene(64, seed=0).frame_at(0.01), scene.frame_at(0.01))
    assert not np.array_equal(demo_scene(64, seed=1).frame_at(0.0), f0)


def test_demo_capture():
    cap = demo_capture(size=32, n_ticks=40)
    assert cap.shape == (40, 32, 32)
    assert cap.cfa == "RGGB"
    assert cap.gt_at(20).shape == (32, 32, 3)
    assert 0.0 < cap.count(0, 40).mean() / 40 < 1.0
