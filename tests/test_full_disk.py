"""A full disk: every writer ends with one sentence and exit 1, no signal, no traceback, nothing left.

Two kinds of test: ``ENOSPC`` injected at the one place each writer's bytes go through
(``os.write``/``os.pwrite``/``os.posix_fallocate``, or the free-space query), which runs
everywhere; and the real thing, the command line writing to a 2 MB tmpfs (where this process may
mount one, i.e. as root), or else under a file-size limit (``RLIMIT_FSIZE``, any user), where the
C libraries behind EXR, PNG and MP4 meet the error themselves.
"""

from __future__ import annotations

import errno
import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spikeview.cli.main import main
from spikeview.export.atomic import PARTIAL_MARKER
from spikeview.io import open_source, write_plain

H, W, T = 64, 96, 400


@pytest.fixture
def capture(tmp_path):
    """A 96×64 RGGB capture with its sidecar, outside the output folder."""
    rng = np.random.default_rng(7)
    rate = rng.uniform(0.05, 0.6, (H, W))  # texture everywhere: no output compresses to nothing
    spikes = rng.random((T, H, W)) < rate
    src = tmp_path / "in" / "cap.dat"
    src.parent.mkdir()
    write_plain(src, spikes, cfa="RGGB")
    out = tmp_path / "out"
    out.mkdir()
    return src, out


def digest(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def one_sentence(err: str, *needles: str) -> None:
    assert "Traceback" not in err, err
    errors = [line for line in err.strip().splitlines() if line.startswith("spikeview: error:")]
    assert len(errors) == 1 and err.strip().endswith(errors[0]), err  # notes may come first; one error, last
    err = errors[0]
    assert "Traceback" not in err and "this is a bug" not in err, err
    for n in needles:
        assert n in err, err


def fail_writes_under(monkeypatch, folder: Path, name: str, budget: int = 0, part: str = "") -> None:
    """Make ``os.<name>`` on files under ``folder`` (whose path holds ``part``) fail with ENOSPC once
    ``budget`` bytes are used."""
    real = getattr(os, name)
    left = [budget]

    def under(fd: int) -> bool:
        try:
            path = os.readlink(f"/proc/self/fd/{fd}")
            return path.startswith(str(folder)) and part in path
        except OSError:
            return False

    def fake(fd, *args):
        if under(fd):
            n = args[1] if name == "posix_fallocate" else len(memoryview(args[0]).cast("B"))
            if n > left[0]:
                raise OSError(errno.ENOSPC, "No space left on device")
            left[0] -= n
        return real(fd, *args)

    monkeypatch.setattr(os, name, fake)


# ------------------------------------------------------------------------------- injected
@pytest.mark.parametrize("name, budget", [("posix_fallocate", 0), ("pwrite", 100_000)])
def test_npy_on_a_full_disk(capture, capsys, monkeypatch, name, budget):
    src, out = capture
    if name == "pwrite":  # the reservation "succeeds" (a filesystem without fallocate), the writes fail
        monkeypatch.setattr(os, "posix_fallocate", lambda fd, off, n: None)
    fail_writes_under(monkeypatch, out, name, budget)
    assert main(["reconstruct", str(src), "--range", "0:400:10", "--out", str(out / "f.npy")]) == 1
    one_sentence(capsys.readouterr().err, "f.npy", "disk is full")
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("name, target", [("posix_fallocate", ".dat"), ("write", ".dat"), ("write", ".gt.npz")])
def test_simulate_on_a_full_disk(tmp_path, capsys, monkeypatch, name, target):
    out = tmp_path / "out"
    out.mkdir()
    fail_writes_under(monkeypatch, out, name, 20_000, f"{target}.tmp")
    assert main(["simulate", "--demo", "--size", "32", "--ticks", "3000", "--gt-every", "10", "--no-noise",
                 "--out", str(out / "s.dat")]) == 1
    one_sentence(capsys.readouterr().err, "s.dat", "disk is full")
    assert list(out.iterdir()) == []


def test_a_disk_too_small_is_refused_before_any_work(capture, capsys, monkeypatch):
    import shutil
    from collections import namedtuple

    src, out = capture
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**9, 10**9 - 5000, 5000))
    assert main(["simulate", "--demo", "--size", "32", "--ticks", "2000", "--out", str(out / "s.dat")]) == 1
    one_sentence(capsys.readouterr().err, "s.dat", "only 5 KB are free")
    assert main(["reconstruct", str(src), "--range", "0:400:10", "--out", str(out / "f.npy")]) == 1
    one_sentence(capsys.readouterr().err, "f.npy", "only 5 KB are free")
    assert list(out.iterdir()) == []


def test_the_recorder_on_a_full_disk_keeps_whole_frames_and_says_why(tmp_path, monkeypatch):
    from spikeview.io import pack_frames
    from spikeview.live.recorder import Recorder

    frame_bytes = 16 * 8 // 8
    fail_writes_under(monkeypatch, tmp_path, "write", budget=10 * frame_bytes + 5)
    rec = Recorder(tmp_path / "r.dat", 16, 8)
    frames = pack_frames(np.random.default_rng(1).random((30, 8, 16)) < 0.5, flip_vertical=False)
    for i in range(0, 30, 3):
        rec.submit(frames[i:i + 3])
    summary = rec.stop(timeout=30)
    assert summary.state == "failed" and summary.frames == 9 and summary.buffer_dropped_frames == 21
    assert "disk is full" in summary.message and "r.dat" in summary.message and "\n" not in summary.message
    assert (tmp_path / "r.dat").read_bytes() == frames[:9].tobytes()  # whole frames only, nothing partial
    with open_source(tmp_path / "r.dat") as src:
        assert src.n_frames == 9 and not src.info.warnings


# --------------------------------------------------------------------- real small disks
def _cli(args: list[str], limit: int | None = None) -> subprocess.CompletedProcess:
    def preexec() -> None:  # pragma: no cover - runs in the child
        import resource
        import signal

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "spikeview", *args], capture_output=True, text=True, timeout=300,
                          preexec_fn=preexec if limit else None, env=env)


WRITERS = [
    ["reconstruct", "{src}", "--range", "0:400:5", "--out", "{out}/f.npy"],
    ["reconstruct", "{src}", "--range", "0:400:5", "--out", "{out}/f_%04d.exr", "--compression", "none"],
    ["reconstruct", "{src}", "--range", "0:400:5", "--out", "{out}/f_%04d.png"],
    ["reconstruct", "{src}", "--range", "0:400:2", "--out", "{out}/f.mp4"],
    ["simulate", "--demo", "--size", "64", "--ticks", "3000", "--gt-every", "10", "--out", "{out}/s.dat"],
]


def _check_clean_failure(proc: subprocess.CompletedProcess, out: Path, before: dict[str, str], src: Path,
                         src_hash: dict[str, str]) -> None:
    assert proc.returncode == 1, (proc.returncode, proc.stderr[-2000:])  # not a signal (negative) nor a crash
    one_sentence(proc.stderr.strip().splitlines()[-1])
    assert "Traceback" not in proc.stderr
    left = {n for n in digest(out)} - set(before)
    # a sequence keeps its finished frames (each file complete); nothing partial or temporary
    assert not [n for n in left if PARTIAL_MARKER in n or ".tmp" in n or n.endswith((".npy", ".mp4", ".dat", ".npz"))], left
    assert digest(src.parent) == src_hash


def _can_mount_tmpfs() -> str:
    """Empty when a tmpfs can be mounted here, else why not."""
    import tempfile

    if os.geteuid() != 0:
        return "mounting a 2 MB tmpfs needs root; the injected-ENOSPC tests cover the same paths"
    with tempfile.TemporaryDirectory() as d:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", d], capture_output=True, text=True)
        if r.returncode != 0:
            return f"cannot mount a tmpfs here ({r.stderr.strip() or r.returncode})"
        subprocess.run(["umount", "-l", d], check=False)
    return ""


NO_TMPFS = _can_mount_tmpfs()


@pytest.mark.skipif(not NO_TMPFS, reason="a real full disk (tmpfs) is tested instead")
@pytest.mark.parametrize("argv", WRITERS, ids=lambda a: Path(a[-1]).suffix if a[-1] != "none" else "exr")
def test_writers_under_a_file_size_limit(capture, argv):
    src, out = capture
    src_hash = digest(src.parent)
    proc = _cli([a.format(src=src, out=out) for a in argv], limit=8_000)
    _check_clean_failure(proc, out, {}, src, src_hash)
    assert "larger than this disk" in proc.stderr or "file-size limit" in proc.stderr or "free" in proc.stderr, proc.stderr


@pytest.fixture
def small_disk(tmp_path):
    mnt = tmp_path / "small"
    mnt.mkdir()
    if NO_TMPFS:
        pytest.skip(NO_TMPFS)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({r.stderr.strip() or r.returncode})")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


@pytest.mark.parametrize("argv", WRITERS, ids=lambda a: Path(a[-1]).suffix if a[-1] != "none" else "exr")
def test_writers_on_a_real_full_disk(capture, small_disk, argv):
    src, _ = capture
    src_hash = digest(src.parent)
    # leave 150 KB free: every output here needs more
    free = os.statvfs(small_disk).f_bavail * os.statvfs(small_disk).f_frsize
    (small_disk / "filler").write_bytes(b"\0" * (free - 150_000))
    before = digest(small_disk)
    proc = _cli([a.format(src=src, out=small_disk) for a in argv])
    _check_clean_failure(proc, small_disk, before, src, src_hash)
    assert "disk is full" in proc.stderr or "are free" in proc.stderr, proc.stderr


def test_recorder_on_a_real_full_disk(small_disk):
    from spikeview.io import pack_frames
    from spikeview.live.recorder import Recorder

    free = os.statvfs(small_disk).f_bavail * os.statvfs(small_disk).f_frsize
    (small_disk / "filler").write_bytes(b"\0" * (free - 64 * 1024))
    frames = pack_frames(np.random.default_rng(2).random((64, 64, 64)) < 0.5, flip_vertical=False)  # 512 B each
    rec = Recorder(small_disk / "r.dat", 64, 64)
    for _ in range(10):
        for i in range(0, 64, 8):
            rec.submit(frames[i:i + 8])
    summary = rec.stop(timeout=30)
    assert summary.state == "failed" and "disk is full" in summary.message
    size = (small_disk / "r.dat").stat().st_size
    assert size % 512 == 0 and size // 512 == summary.frames > 0
