"""A plain 400x250 .dat read as a raw 400x250 stream is refused; real raw 400x250 streams still open.

A raw 400x250 frame is 250 rows of 416 bits (13,000 bytes), a plain one 250 rows of 400 bits (12,500 bytes).
Read as raw, a plain file is 50-byte rows cut at 52 bytes: a sheared picture, which the reader used to accept
with only a partial-frame warning (newcomer walk-through, session 4, item 7).
"""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main
from spikeview.errors import InputFileError
from spikeview.io import open_source, write_plain
from spikeview.io.raw400 import Raw400Source, encode_raw400, plain_400x250_evidence

W, H = 400, 250


def _scene(seed: int) -> np.ndarray:
    """A smooth scene (blobs and a slanted wave), linear RGB in [0.1, 0.9]."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W] / W
    img = np.zeros((H, W))
    for _ in range(5):
        cx, cy, s = rng.uniform(0, 1), rng.uniform(0, 0.6), rng.uniform(0.05, 0.2)
        img += rng.uniform(0.3, 1) * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * s * s))
    img += 0.3 * np.sin(2 * np.pi * (3 * xx + 2 * yy))
    img = 0.1 + 0.8 * (img - img.min()) / (img.max() - img.min())
    return np.repeat(img[..., None], 3, axis=-1).astype(np.float32)


def _simulated(tmp_path, cfa: str, ticks: int = 40) -> tuple:
    """A plain 400x250 capture from the simulator (integrate-and-fire pixels) without sidecar, and its frames."""
    from spikeview.sim import MotionScene, SimConfig, simulate_to_file

    scene = MotionScene(_scene(3), (H, W), pan=(200.0, 50.0))
    files = simulate_to_file(scene, SimConfig(n_ticks=ticks, width=W, height=H, cfa=cfa, seed=2), tmp_path / "sim.dat")
    files.sidecar.unlink()
    with open_source(files.dat, width=W, height=H, cfa=None if cfa == "none" else cfa) as src:
        frames = src.read(0, src.n_frames)
    return files.dat, frames


def _bernoulli(cfa: str, ticks: int = 40) -> np.ndarray:
    """Spikes drawn independently per tick (no integrate-and-fire signature): only the scene marks the frame size."""
    rate = 0.05 + 0.5 * _scene(5)[..., 0]
    if cfa != "none":
        rate[0::2, 0::2] *= 0.6
        rate[1::2, 1::2] *= 0.5
    rng = np.random.default_rng(7)
    return (rng.random((ticks, H, W), dtype=np.float32) < rate).astype(np.uint8)


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_a_plain_capture_read_as_raw400_is_refused_in_one_sentence(tmp_path, capsys, cfa):
    path, frames = _simulated(tmp_path, cfa)
    with pytest.raises(InputFileError, match=r"sim\.dat: has no raw 400x250 rows of 416 bits.*repeat every 12500 bytes"
                                             r".*looks like a plain 400x250 \.dat; drop --format raw400 or use "
                                             r"--format plain\.$"):
        open_source(path, format="raw400")
    # a partial last frame (the Spike-Zoo case: 301 plain frames = 289 raw frames and 5,500 bytes) changes nothing
    cut = tmp_path / "cut.dat"
    cut.write_bytes(path.read_bytes()[:-700])
    with pytest.raises(InputFileError, match="looks like a plain 400x250"):
        Raw400Source(cut)
    assert main(["info", str(path), "--format", "raw400", "--cfa", cfa]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "drop --format raw400 or use --format plain" in err, err
    assert "Traceback" not in err
    # the fix the sentence names works
    assert main(["info", str(path), "--format", "plain", "--width", "400", "--height", "250", "--cfa", cfa]) == 0
    # the same spikes written as a raw stream open as before, pixel for pixel
    raw = tmp_path / "sim.r400"
    raw.write_bytes(encode_raw400(frames))
    with open_source(raw, format="raw400", cfa=None if cfa == "none" else cfa) as src:
        assert src.info.format == "raw400" and src.n_frames == frames.shape[0]
        np.testing.assert_array_equal(src.read(0, src.n_frames), frames)
    assert plain_400x250_evidence(np.fromfile(raw, np.uint8)) is None


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_the_scene_alone_tells_plain_from_raw_without_integrate_and_fire(tmp_path, cfa):
    """Bernoulli spikes carry no tick-to-tick signature: the scene's repetition every 12,500 bytes decides."""
    spikes = _bernoulli(cfa)
    plain = write_plain(tmp_path / "b.dat", spikes, sidecar=False)
    with pytest.raises(InputFileError, match="its scene repeats every 12500 bytes"):
        Raw400Source(plain)
    raw = tmp_path / "b.r400"
    data = np.frombuffer(encode_raw400(spikes), np.uint8).copy().reshape(-1, H, 52)
    data[:, :, 50:] = np.random.default_rng(1).integers(0, 256, data[:, :, 50:].shape, dtype=np.uint8)  # any tag bits
    raw.write_bytes(data.tobytes())
    with Raw400Source(raw) as src:
        np.testing.assert_array_equal(src.read(0, src.n_frames), spikes)


def test_no_scene_no_verdict(tmp_path):
    """Black and random files give no evidence either way: read as raw when asked, as before."""
    zeros = tmp_path / "z.bin"
    zeros.write_bytes(bytes(13_000 * 6))
    assert plain_400x250_evidence(np.fromfile(zeros, np.uint8)) is None
    noise = tmp_path / "n.bin"
    noise.write_bytes(np.random.default_rng(0).integers(0, 256, 12_500 * 26, dtype=np.uint8).tobytes())
    with Raw400Source(noise) as src:
        assert src.n_frames == 25


def test_a_plain_capture_cut_to_whole_raw_frames_is_detected_as_plain(tmp_path):
    """Without --format, a size of whole raw frames used to decide raw400; the spikes now overrule it."""
    path, frames = _simulated(tmp_path, "none")
    cut = tmp_path / "cut.dat"
    cut.write_bytes(path.read_bytes()[:13_000 * 37])  # 481,000 bytes: 37 raw frames, 38.48 plain frames
    for kwargs in ({}, {"width": W, "height": H}):
        with open_source(cut, **kwargs) as src:
            assert src.info.format == "plain" and src.n_frames == 38, kwargs
            assert any("read as a plain 400x250 file although its size is whole raw" in w for w in src.info.warnings)
            np.testing.assert_array_equal(src.read(0, 38), frames[:38])
