"""The README's Usage examples, run one after another at small sizes: exit 0, and no input ever changes.

Every ```bash block of the README's "Usage" section is read and each ``spikeview`` command is run
in-process, in order, in a temporary folder holding small stand-ins for the user's files (a capture, a raw
camera stream, an array, a video, a photo, a folder of frames). Sizes, tick counts and ranges are shrunk
(``--size``/``--width``/``--height`` to 32, tick counts and ranges divided by 10, at most 4 windows per
range) so that the whole sequence takes seconds; everything else runs as written. Left out: the app
(``spikeview`` alone needs a display), the ``--prior sd`` line (needs a Stable Diffusion model folder),
the benchmarks, the SLURM example (it joins a scheduler on a cluster), and ``--cluster`` (workers run
in-process here: starting Dask workers on the shared test
machine costs more than the examples themselves).
"""

from __future__ import annotations

import hashlib
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from spikeview.cli.main import main

README = Path(__file__).resolve().parents[1] / "README.md"
SMALL = 32  # frame size of the shrunk simulations
TICK_DIVISOR = 10
MAX_WINDOWS = 4


def usage_commands() -> list[list[str]]:
    text = README.read_text(encoding="utf-8")
    start = text.index("\n## Usage")
    end = text.find("\n## ", start + 1)
    section = text[start:end if end > 0 else None]
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", section, re.S):
        for line in block.replace("\\\n", " ").splitlines():  # join continued lines
            argv = shlex.split(line, comments=True)
            if argv:
                commands.append(argv)
    return commands


def skipped(argv: list[str]) -> bool:
    if argv[0] == "python" or argv == ["spikeview"] or argv[:2] == ["spikeview", "bench"]:
        return True
    if any(a.startswith("tcp://") for a in argv):  # joins a running Dask scheduler on a cluster
        return True
    return "--prior" in argv and argv[argv.index("--prior") + 1] == "sd"


def shrink(argv: list[str]) -> list[str]:
    out: list[str] = []
    it = iter(argv)
    for tok in it:
        if tok == "--cluster":
            next(it)
            continue
        out.append(tok)
        if tok in ("--size", "--width", "--height"):
            value = int(next(it))
            out.append(str(64 if argv[1] in ("info", "reconstruct") and value == 1000 else SMALL))
        elif tok in ("--ticks", "--at"):
            out.append(str(int(next(it)) // TICK_DIVISOR))
        elif tok == "--range":
            a, b, *step = (int(v) for v in next(it).split(":"))
            a, b = a // TICK_DIVISOR, b // TICK_DIVISOR
            s = step[0] if step else 10
            out.append(f"{a}:{min(b, a + MAX_WINDOWS * s)}:{s}")
        elif tok == "--steps":
            out.append(str(min(int(next(it)), 4)))
    return out


def make_inputs(folder: Path) -> list[Path]:
    """Small stand-ins for the files the README's examples read; returns them."""
    import av
    import OpenImageIO as oiio

    from spikeview.io import write_array, write_plain
    from spikeview.io.raw1m import write_raw1m

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:64, 0:64] / 64.0
    rate = (0.1 + 0.4 * (np.sin(6 * xx) * np.cos(4 * yy) + 1) / 2).astype(np.float32)
    inputs = [write_plain(folder / "capture.dat", rng.random((100, 64, 64), dtype=np.float32) < rate, cfa="BGGR")]
    inputs.append(folder / "capture.dat.toml")
    for name, level in (("dark", 0.005), ("flat", 0.4)):  # the camera's calibration captures (README: calibrate)
        inputs.append(write_plain(folder / f"{name}.dat", rng.random((100, 64, 64), dtype=np.float32) < level, cfa="BGGR"))
        inputs.append(folder / f"{name}.dat.toml")
    inputs.append(write_raw1m(folder / "recording.raw", rng.random((2, 1000, 1000)) < 0.2, sidecar=False))
    real = folder / "tests" / "data" / "uhsr.npz"  # the real dark capture the README names (README: dark and real)
    real.parent.mkdir(parents=True)
    real.write_bytes((Path(__file__).parent / "data" / "uhsr.npz").read_bytes())
    inputs.append(real)
    inputs.append(write_array(folder / "spikes.npz", (rng.random((40, 16, 24)) < 0.3).transpose(1, 2, 0),
                              sidecar=False))

    def image(t: float) -> np.ndarray:
        return (np.clip(0.5 + 0.4 * np.sin(8 * xx[..., None] + t + np.arange(3)), 0, 1) * 255).astype(np.uint8)

    clip = folder / "clip.mp4"
    with av.open(str(clip), "w") as c:
        s = c.add_stream("libx264", rate=30)
        s.width = s.height = 64
        s.pix_fmt = "yuv420p"
        for i in range(12):
            for p in s.encode(av.VideoFrame.from_ndarray(image(i / 3), format="rgb24")):
                c.mux(p)
        for p in s.encode(None):
            c.mux(p)
    inputs.append(clip)
    frames = folder / "frames"
    frames.mkdir()
    for i in range(101):  # 0.1 s at --fps 1000: the default 2000 ticks
        out = oiio.ImageOutput.create(str(frames / f"f{i:03d}.png"))
        out.open(str(frames / f"f{i:03d}.png"), oiio.ImageSpec(64, 64, 3, "uint8"))
        out.write_image(image(i / 20))
        out.close()
    (frames / "notes.txt").write_text("not a frame\n")
    inputs += sorted(frames.iterdir())
    photo = folder / "photo.png"
    photo.write_bytes((frames / "f000.png").read_bytes())
    inputs.append(photo)
    return inputs


def digest(paths: list[Path]) -> dict[str, str]:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in paths}


def test_readme_usage_examples_run_in_sequence_without_clobbering(tmp_path, monkeypatch, capsys):
    commands = usage_commands()
    assert any(c[:2] == ["spikeview", "simulate"] for c in commands)  # the section was found
    monkeypatch.chdir(tmp_path)
    inputs = make_inputs(tmp_path)
    before = digest(inputs)
    frames_before = sorted(p.name for p in (tmp_path / "frames").iterdir())
    ran = []
    for argv in commands:
        if skipped(argv):
            continue
        if argv[0] == "mkdir":
            for d in argv[1:]:
                if not d.startswith("-"):
                    Path(d).mkdir(parents=True, exist_ok=True)
            continue
        assert argv[0] == "spikeview", argv
        small = shrink(argv)
        code = main(small[1:])
        out = capsys.readouterr()
        assert code == 0, f"{' '.join(small)} exited {code}:\n{out.err[-2000:]}"
        ran.append(small[1])
    assert {"info", "simulate", "reconstruct"} <= set(ran)
    assert digest(inputs) == before, "an example changed one of its inputs"
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == frames_before, "an example wrote into frames/"


def test_running_an_example_again_refuses_instead_of_overwriting(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = shrink(["spikeview", "simulate", "--demo", "--size", "256", "--ticks", "2000", "--out", "demo.dat"])
    assert main(argv[1:]) == 0
    first = (tmp_path / "demo.dat").read_bytes()
    capsys.readouterr()
    assert main([*argv[1:-2], "--seed", "5", "--out", "demo.dat"]) == 1
    assert "demo.dat: the file already exists" in capsys.readouterr().err
    assert (tmp_path / "demo.dat").read_bytes() == first
    assert main([*argv[1:-2], "--seed", "5", "--overwrite", "--out", "demo.dat"]) == 0
    assert (tmp_path / "demo.dat").read_bytes() != first


@pytest.mark.parametrize("argv", [c for c in usage_commands() if not skipped(c) and c[0] == "spikeview"],
                         ids=lambda c: " ".join(c[1:3]))
def test_every_example_names_an_output_no_other_example_names(argv):
    outs = [c[c.index("--out") + 1] for c in usage_commands() if "--out" in c and "--resume" not in c]
    if "--out" in argv:
        out = argv[argv.index("--out") + 1]
        assert outs.count(out) == 1 or "--resume" in argv, f"{out} is written by more than one example"
