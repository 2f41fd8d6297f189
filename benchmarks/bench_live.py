"""Sustained decode throughput of the tagged raw 1000×1000 stream, through the mock USB backend.

What it measures (raw bytes in per wall-clock second, and frames per second; 128,000 bytes per frame):

* **end to end**: :class:`spikeview.live.usb.UsbCamera` on :class:`spikeview.live.mockusb.MockBackend`
  (pyusb → 2 MiB bulk reads → :class:`~spikeview.io.raw1m.Raw1MDecoder` synchronisation → tag
  stripping → ring buffer), without and with recording to disk, and with a host-side ROI or
  decimation;
* **stages alone**, to find the bottleneck: the mock + pyusb read loop (no decoding),
  ``Raw1MDecoder.feed_raw`` (synchronisation, frames as raw bytes), :func:`raw1m_to_packed` (tag
  stripping), and ``Raw1MDecoder.feed`` (the decoder's own decoded output: unpacked uint8 frames).

Compared with the practical USB 3 rate (about 400 MB/s) and the sensor's own rate (20,000 frames/s
× 128,000 bytes = 2.56 GB/s). Medians of ``--runs`` runs after one warm-up run; the input is 32
distinct random frames (25 % spikes) repeated, cut into 2 MiB transfers.

Usage::

    python benchmarks/bench_live.py                  # writes benchmarks/results/live.md
    python benchmarks/bench_live.py --mb 64 --runs 3 --out /tmp/live.md   # smoke run
"""

from __future__ import annotations

import argparse
import array
import os
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from _common import cpu_model, load_average, write_report  # noqa: E402  (benchmarks/_common.py)
from spikeview.io.raw1m import RAW1M_FRAME_BYTES, Raw1MDecoder, encode_raw1m  # noqa: E402
from spikeview.live.decode import raw1m_to_packed  # noqa: E402
from spikeview.live.mockusb import MOCK_PID, MOCK_VID, MockBackend  # noqa: E402
from spikeview.live.usb import CameraConfig, UsbCamera  # noqa: E402

TRANSFER = 2 << 20
USB3_BPS = 400e6
SENSOR_BPS = 20_000 * RAW1M_FRAME_BYTES
N_DISTINCT = 32


def make_stream() -> np.ndarray:
    rng = np.random.default_rng(0)
    frames = (rng.random((N_DISTINCT, 1000, 1000)) < 0.25).astype(np.uint8)
    return np.frombuffer(encode_raw1m(frames), dtype=np.uint8)


def transfers(raw: np.ndarray, total: int):
    """Yield ``total`` bytes of the repeated stream as 2 MiB transfers (memoryviews, no copies)."""
    doubled = np.concatenate([raw, raw[:TRANSFER]])
    pos = sent = 0
    while sent < total:
        k = min(TRANSFER, total - sent)
        yield memoryview(doubled[pos:pos + k])
        pos = (pos + k) % raw.size
        sent += k


def timed(fn: Callable[[], int], runs: int) -> tuple[float, float, int]:
    """Median wall seconds, median CPU seconds (process), bytes per run; one warm-up run first."""
    fn()
    walls, cpus = [], []
    nbytes = 0
    for _ in range(runs):
        c0, t0 = time.process_time(), time.perf_counter()
        nbytes = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return statistics.median(walls), statistics.median(cpus), nbytes


# ------------------------------------------------------------------------------------------ cases
def case_pyusb_only(raw: np.ndarray, total: int) -> int:
    import usb.core

    dev = usb.core.find(idVendor=MOCK_VID, backend=MockBackend(transfers(raw, total), then="disconnect"))
    dev.set_configuration()
    buf = array.array("B", bytes(TRANSFER))
    got = 0
    try:
        while True:
            got += dev.read(0x81, buf, 1000)
    except usb.core.USBError:
        pass
    return got


def case_feed_raw(raw: np.ndarray, total: int) -> int:
    dec = Raw1MDecoder()
    for chunk in transfers(raw, total):
        dec.feed_raw(chunk)
    assert dec.stats.skipped_bytes == 0
    return total


def case_strip(raw: np.ndarray, total: int) -> int:
    n = total // raw.size
    for _ in range(max(n, 1)):
        raw1m_to_packed(raw)
    return max(n, 1) * raw.size


def case_feed_decoded(raw: np.ndarray, total: int) -> int:
    dec = Raw1MDecoder()
    for chunk in transfers(raw, total):
        dec.feed(chunk)
    return total


def case_camera(raw: np.ndarray, total: int, record_dir: str | None = None, **settings: object) -> int:
    be = MockBackend(transfers(raw, total), then="disconnect")
    cam = UsbCamera(CameraConfig(vid=MOCK_VID, pid=MOCK_PID, transfer_bytes=TRANSFER, **settings), backend=be)
    path = None
    if record_dir is not None:
        path = Path(record_dir) / "bench.dat"
        path.unlink(missing_ok=True)
        cam.start_recording(path)
    cam.start()
    if not cam.wait(600):
        raise RuntimeError("the acquisition did not finish")
    cam.close()  # waits for the recording (flush + fsync) too
    expected = total // RAW1M_FRAME_BYTES
    if cam.n_frames != -(-expected // int(settings.get("frame_step", 1))):  # frames 0, step, 2·step …
        raise RuntimeError(f"decoded {cam.n_frames} frames, expected {expected}: {cam.status_message}")
    if path is not None:
        path.unlink()
    return be.sent_bytes


# ------------------------------------------------------------------------------------------ report
def machine() -> str:
    model = cpu_model()
    return (f"{platform.platform()}, {model}, os.cpu_count() = {os.cpu_count()}, Python {platform.python_version()}, "
            f"numpy {np.__version__}")


def findings(rows: list[tuple[str, float, float, int, str]]) -> list[str]:
    """A short reading of the table, from its numbers (per CPU-second, so other jobs on the machine matter less)."""
    per_cpu = {name.split(":")[0] if name.startswith("stage") else name: nbytes / max(cpu, 1e-9)
               for name, wall, cpu, nbytes, note in rows}
    wall_bps = {name: nbytes / wall for name, wall, cpu, nbytes, note in rows}

    def get(prefix: str, table: dict[str, float]) -> float:
        return next(v for k, v in table.items() if k.startswith(prefix))

    e2e = get("end to end: UsbCamera", per_cpu)
    sync = next(v for k, v in ((n, nb / max(c, 1e-9)) for n, w, c, nb, _ in rows) if "feed_raw" in k)
    strip = next(v for k, v in ((n, nb / max(c, 1e-9)) for n, w, c, nb, _ in rows) if "tag stripping" in k)
    unpack = next(v for k, v in ((n, nb / max(c, 1e-9)) for n, w, c, nb, _ in rows) if "unpack to uint8" in k)
    dec = next(v for k, v in ((n, nb / max(c, 1e-9)) for n, w, c, nb, _ in rows) if "decimate" in k)
    usb = next(v for k, v in ((n, nb / max(c, 1e-9)) for n, w, c, nb, _ in rows) if "pyusb bulk reads" in k)
    share_sync, share_strip = e2e / sync, e2e / strip
    wall = get("end to end: UsbCamera", wall_bps)
    return [
        "",
        "## Reading the numbers",
        "",
        f"- The live path (no ROI) decodes {wall / 1e6:,.0f} MB/s wall-clock here ({e2e / 1e6:,.0f} MB per CPU-second): "
        f"{e2e / USB3_BPS:.1f}× what a USB 3 link delivers, {e2e / SENSOR_BPS:.2f}× the sensor's 2.56 GB/s. A real "
        f"camera is therefore limited by USB, not by decoding; the full sensor rate is out of reach of USB anyway.",
        f"- Per byte, `Raw1MDecoder.feed_raw` (tag check, buffering, one copy per frame) is {share_sync:.0%} of the "
        f"end-to-end CPU cost, tag stripping (`raw1m_to_packed`, numba) {share_strip:.0%}, the mock + pyusb transfers "
        f"{e2e / usb:.0%}; the remaining {max(0.0, 1 - share_sync - share_strip - e2e / usb):.0%} is mostly the ring copy (whose first "
        f"lap also pays the page faults of fresh memory: every run here starts a new camera) and per-batch bookkeeping. `Raw1MDecoder` is not the bottleneck of the live path.",
        f"- `Raw1MDecoder.feed` (frames unpacked to one byte per pixel) runs at {unpack / 1e6:,.0f} MB per CPU-second, "
        f"{sync / unpack:.1f}× slower than `feed_raw`: writing 8× the data dominates. It is "
        f"{unpack / USB3_BPS:.1f}× the USB 3 rate but {SENSOR_BPS / unpack:.1f}× short of the sensor rate; the live "
        f"path never unpacks whole frames (the ring and the recorder keep them packed).",
        f"- Host-side decimation unpacks the kept rows and repacks them: {dec / 1e6:,.0f} MB per CPU-second "
        f"({dec / USB3_BPS:.2f}× USB 3). To cut data at full USB 3 rate use a byte-aligned ROI (left and width "
        f"multiples of 8: no unpacking at all) or `frame_step`.",
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, default=256.0, help="raw MB per run of the fast cases (default 256)")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "live.md")
    ap.add_argument("--dir", default=None, help="folder for the recording case (default: the temp folder)")
    args = ap.parse_args(argv)

    raw = make_stream()
    frame_total = int(args.mb * 1e6) // RAW1M_FRAME_BYTES
    total = frame_total * RAW1M_FRAME_BYTES
    slow_total = max(total // 8, 32 * RAW1M_FRAME_BYTES)
    load_before = load_average("/")
    rows: list[tuple[str, float, float, int, str]] = []

    def run(name: str, fn: Callable[[], int], note: str = "") -> None:
        wall, cpu, nbytes = timed(fn, args.runs)
        rows.append((name, wall, cpu, nbytes, note))
        print(f"{name}: {nbytes / wall / 1e6:,.0f} MB/s ({nbytes / RAW1M_FRAME_BYTES / wall:,.0f} frames/s), "
              f"CPU {cpu / wall:.2f} cores, {nbytes / max(cpu, 1e-9) / 1e6:,.0f} MB per CPU-s", flush=True)

    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        run("end to end: UsbCamera (mock USB → decode → ring)", lambda: case_camera(raw, total))
        run("end to end + recording to plain .dat (fsync at stop)", lambda: case_camera(raw, total, tmp),
            "disk-bound; page cache absorbs most of it")
        run("end to end, ROI 256×256 (byte-aligned, no unpacking)", lambda: case_camera(raw, total, roi=[372, 368, 256, 256]))
        run("end to end, ROI 500×500 at column 4 (unpacks the ROI rows)",
            lambda: case_camera(raw, total, roi=[250, 4, 500, 500]))
        run("end to end, decimate 2 (mono)", lambda: case_camera(raw, total, decimate=2))
        run("end to end, frame_step 4", lambda: case_camera(raw, total, frame_step=4))
        run("stage: mock + pyusb bulk reads only", lambda: case_pyusb_only(raw, total))
        run("stage: Raw1MDecoder.feed_raw (sync, raw frames)", lambda: case_feed_raw(raw, total))
        run("stage: raw1m_to_packed (tag stripping)", lambda: case_strip(raw, total))
        run("stage: Raw1MDecoder.feed (sync + unpack to uint8 frames)", lambda: case_feed_decoded(raw, slow_total),
            "not used by the live path")
    load_after = load_average("/")

    lines = [
        "# Live capture: sustained decode throughput of the raw 1000×1000 stream",
        "",
        f"Generated by `benchmarks/bench_live.py` on {time.strftime('%Y-%m-%d %H:%M')}.",
        "",
        f"- Machine: {machine()}.",
        f"- Load average (1/5/15 min) before: {load_before}, after: {load_after} (other jobs share the machine).",
        f"- Input: {N_DISTINCT} distinct random frames (25 % spikes) encoded with `encode_raw1m`, repeated; "
        f"{total / 1e6:.0f} MB ({frame_total} frames) per run ({slow_total / 1e6:.0f} MB for the slow stage), "
        f"{TRANSFER >> 20} MiB transfers; median of {args.runs} runs after a warm-up run.",
        f"- Reference rates: practical USB 3 ≈ {USB3_BPS / 1e6:.0f} MB/s ({USB3_BPS / RAW1M_FRAME_BYTES:,.0f} frames/s); "
        f"sensor {SENSOR_BPS / 1e9:.2f} GB/s (20,000 frames/s).",
        "- 'CPU' is process CPU time / wall time (all threads: acquisition, recorder writer); below 1 for a "
        "single-threaded case means other jobs took the core part of the time. 'MB per CPU-s' divides by the "
        "process CPU time instead: about what an otherwise idle core would do (the recording case also waits on the disk).",
        "",
        "| case | MB/s (wall) | frames/s (wall) | × USB 3 | × sensor | CPU (cores) | MB per CPU-s | note |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for name, wall, cpu, nbytes, note in rows:
        bps = nbytes / wall
        lines.append(f"| {name} | {bps / 1e6:,.0f} | {bps / RAW1M_FRAME_BYTES:,.0f} | {bps / USB3_BPS:.2f} | "
                     f"{bps / SENSOR_BPS:.2f} | {cpu / wall:.2f} | {nbytes / max(cpu, 1e-9) / 1e6:,.0f} | {note} |")
    lines += findings(rows)
    return write_report(args.out, lines)


if __name__ == "__main__":
    raise SystemExit(main())
