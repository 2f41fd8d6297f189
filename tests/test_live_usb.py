"""The USB camera on a mock pyusb backend: decoding, faults, statuses, and what the recording holds.

Every fault scenario checks three things: the status and its message (one sentence with the fix),
that the acquisition thread ended by itself (no crash, no hang), and that the recording holds
every complete frame the mock sent before the fault, byte for byte.
"""

from __future__ import annotations

import errno

import numpy as np
import pytest
import usb.core

from spikeview.errors import OutputFileError, ParameterError
from spikeview.io import encode_raw1m, open_source, pack_frames, read_sidecar
from spikeview.live import LiveStatus
from spikeview.live.mockusb import MOCK_PID, MOCK_VID, Fault, MockBackend
from spikeview.live.ring import RingOverrun
from spikeview.live.usb import CameraConfig, UsbCamera, list_usb_devices, udev_rule

FRAME = 128_000  # bytes of one raw 1000×1000 frame
T = 8  # frames the mock camera has to send
WAIT_S = 30  # generous: the machine is shared; nothing here measures speed


@pytest.fixture(scope="module")
def frames() -> np.ndarray:
    rng = np.random.default_rng(2024)
    return (rng.random((T, 1000, 1000)) < 0.25).astype(np.uint8)


@pytest.fixture(scope="module")
def raw(frames) -> bytes:
    return encode_raw1m(frames)


def camera(backend: MockBackend, **settings) -> UsbCamera:
    return UsbCamera(CameraConfig(vid=MOCK_VID, pid=MOCK_PID, **settings), backend=backend)


def run_recorded(cam: UsbCamera, path) -> None:
    """Record from the first frame, run the script to its end, close."""
    cam.start_recording(path)
    cam.start()
    assert cam.wait(WAIT_S), "the acquisition thread did not end"
    cam.close(timeout=WAIT_S)


def assert_recording(path, expected: np.ndarray) -> dict:
    """The .dat holds exactly ``expected`` (as plain packed bytes) and reads back through open_source."""
    want = pack_frames(expected, flip_vertical=False).tobytes() if len(expected) else b""
    assert path.read_bytes() == want
    table = read_sidecar(path).tables["recording"]
    assert table["frames"] == len(expected)
    assert table["state"] == "complete"
    if len(expected):
        with open_source(path) as src:
            assert src.n_frames == len(expected)
            np.testing.assert_array_equal(src.read(0, src.n_frames), expected)
    return table


# ------------------------------------------------------------------------------------- listing


def test_lists_the_mock_camera_with_its_names():
    devices = list_usb_devices(MockBackend())
    assert len(devices) == 1
    d = devices[0]
    assert (d.vid, d.pid, d.product) == (MOCK_VID, MOCK_PID, "Mock spike camera")
    assert "f055:5b1c" in d.label and "Mock spike camera" in d.label
    assert list_usb_devices(MockBackend(), vid=0x1234) == []


def test_finds_the_device_through_pyusb():
    dev = usb.core.find(idVendor=MOCK_VID, backend=MockBackend())
    assert dev is not None and dev.idProduct == MOCK_PID


# ------------------------------------------------------------------------------------- a clean stream


def test_clean_stream_is_decoded_and_recorded(tmp_path, frames, raw):
    be = MockBackend([raw[:300_000], raw[300_000:]], max_read=100_000)  # then the camera stops sending
    statuses = []
    cam = UsbCamera(CameraConfig(vid=MOCK_VID, pid=MOCK_PID, max_timeouts=2), backend=be,
                    on_status=lambda s, m: statuses.append(s))
    run_recorded(cam, tmp_path / "clean.dat")
    assert cam.status is LiveStatus.TIMEOUT
    changes = [st for i, st in enumerate(statuses) if i == 0 or st != statuses[i - 1]]
    assert changes == [LiveStatus.CONNECTING, LiveStatus.RUNNING, LiveStatus.WAITING, LiveStatus.TIMEOUT]
    assert cam.n_frames == T
    np.testing.assert_array_equal(cam.read(2, 5), frames[2:5])
    np.testing.assert_array_equal(cam.latest(2), frames[-2:])
    table = assert_recording(tmp_path / "clean.dat", frames)
    assert table["device_dropped_frames"] == 0 and table["buffer_dropped_frames"] == 0
    assert be.claimed == set()  # the interface was released
    assert be.sent_bytes == len(raw)


def test_reads_of_overwritten_ticks_say_what_is_left(raw):
    cam = camera(MockBackend([raw]), ring_mb=0.3, max_timeouts=1)  # 0.3 MiB: 2 frames
    cam.start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.TIMEOUT
    assert cam.oldest_tick == T - 2
    with pytest.raises(RingOverrun, match=r"holds ticks \[6, 8\)"):
        cam.read(0, 3)
    assert cam.stats()["ring_overruns"] == 1
    cam.close()


# ------------------------------------------------------------------------------------- faults


def _cut(raw: bytes, frame: int, offset: int = 0) -> int:
    return frame * FRAME + offset


SCENARIOS = {
    # name: (script builder, camera settings, status, message fragment, expected frame indices, counters)
    "disconnect mid-transfer": (
        lambda r: [r[:_cut(r, 5, 60_000)], Fault("disconnect")], {},
        LiveStatus.DISCONNECTED, "was disconnected", list(range(5)), {"device_trailing_bytes": 60_000}),
    "disconnect mid-block": (
        lambda r: [r[:_cut(r, 3, 33)], Fault("disconnect")], {},
        LiveStatus.DISCONNECTED, "plug it in again", list(range(3)), {}),
    "timeout gives up": (
        lambda r: [r[:_cut(r, 4)], Fault("timeout"), r[_cut(r, 4):]], {"max_timeouts": 1},
        LiveStatus.TIMEOUT, "sent no data", list(range(4)), {"device_timeouts": 1}),
    "timeout recovers": (
        lambda r: [r[:_cut(r, 4, 500)], Fault("timeout"), Fault("timeout"), r[_cut(r, 4, 500):], Fault("disconnect")],
        {"max_timeouts": 3},
        LiveStatus.DISCONNECTED, "was disconnected", list(range(T)), {"device_timeouts": 2}),
    "pipe error gives up": (
        lambda r: [r[:_cut(r, 2, 70_000)], Fault("pipe"), r[_cut(r, 2, 70_000):]], {"max_pipe_errors": 0},
        LiveStatus.PIPE_ERROR, "stalled (pipe error)", list(range(2)), {"device_pipe_errors": 1}),
    "pipe error cleared": (
        lambda r: [r[:_cut(r, 2, 70_000)], Fault("pipe"), r[_cut(r, 2, 70_000):], Fault("disconnect")], {},
        LiveStatus.DISCONNECTED, "was disconnected", list(range(T)), {"device_pipe_errors": 1}),
    "io error": (
        lambda r: [r[:_cut(r, 6)], Fault("io")], {},
        LiveStatus.DISCONNECTED, "I/O error", list(range(6)), {}),
    "garbage between frames": (
        lambda r: [r[:_cut(r, 3)], np.random.default_rng(9).integers(0, 256, 5000, dtype=np.uint8).tobytes(),
                   r[_cut(r, 3):], Fault("disconnect")], {},
        LiveStatus.DISCONNECTED, "was disconnected", list(range(T)),
        {"device_skipped_bytes": 5000, "device_resyncs": 1, "device_dropped_frames": 0}),
    "capture starts mid-frame": (
        lambda r: [r[_cut(r, 0, 100_001):], Fault("disconnect")], {},
        LiveStatus.DISCONNECTED, "was disconnected", list(range(1, T)), {"device_leading_bytes": FRAME - 100_001}),
    "corrupted tag": (
        lambda r: [_corrupt_tag(r, frame=3), Fault("disconnect")], {},
        LiveStatus.DISCONNECTED, "was disconnected", [0, 1, 2, 4, 5, 6, 7],
        {"device_dropped_frames": 1, "device_resyncs": 1, "device_skipped_bytes": FRAME}),
    # frames 2-4 are damaged (2 and 4 partly lost, 3 wholly): the raw stream has no frame counter, so the
    # decoder can only estimate drops from the bytes that did arrive (124,000 stray bytes: about one frame)
    "frames lost in transit": (
        lambda r: [r[:_cut(r, 2, 1000)], r[_cut(r, 4, 5000):], Fault("disconnect")], {},
        LiveStatus.DISCONNECTED, "was disconnected", [0, 1, 5, 6, 7],
        {"device_dropped_frames": 1, "device_resyncs": 1, "device_skipped_bytes": 1000 + FRAME - 5000}),
}


def _corrupt_tag(raw: bytes, frame: int) -> bytes:
    b = bytearray(raw)
    b[frame * FRAME + 700 * 64 + 63] ^= 0x40  # the tag of block 700 names another line
    return bytes(b)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_fault_keeps_every_complete_frame(tmp_path, frames, raw, name):
    build, settings, status, fragment, expected, counters = SCENARIOS[name]
    be = MockBackend(build(raw), max_read=64_000)
    cam = camera(be, **settings)
    path = tmp_path / "rec.dat"
    run_recorded(cam, path)
    assert cam.status is status, cam.status_message
    assert fragment in cam.status_message
    assert cam.status_message.endswith(".")
    assert not cam.running
    table = assert_recording(path, frames[expected])
    for key, value in counters.items():
        assert table[key] == value, (key, table)
    assert table["end"] == cam.status_message


def test_pipe_error_is_cleared_before_retrying(raw):
    be = MockBackend([raw[:1000], Fault("pipe"), raw[1000:]], then="disconnect")
    cam = camera(be).start()
    assert cam.wait(WAIT_S)
    assert be.clear_halts == 1 and cam.n_frames == T
    cam.close()


# ------------------------------------------------------------------------------------- opening problems


def test_device_not_found_names_the_ids(tmp_path):
    cam = UsbCamera(CameraConfig(vid=0x1234, pid=0x0001), backend=MockBackend())
    cam.start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.NOT_FOUND
    assert "1234:0001" in cam.status_message and "lsusb" in cam.status_message
    assert cam.status.failed and not cam.status.active
    cam.close()


def test_no_ids_is_not_found_with_the_fix():
    cam = UsbCamera(CameraConfig(), backend=MockBackend()).start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.NOT_FOUND and "vid, pid" in cam.status_message
    cam.close()


def test_permission_denied_gives_the_udev_rule(tmp_path):
    be = MockBackend(open_error="access")
    cam = camera(be)
    rec = cam.start_recording(tmp_path / "denied.dat")
    cam.start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.PERMISSION_DENIED
    msg = cam.status_message
    assert udev_rule(MOCK_VID, MOCK_PID) in msg
    assert 'ATTRS{idVendor}=="f055"' in msg and "/etc/udev/rules.d/" in msg and "udevadm" in msg
    assert rec.state == "done"  # the (empty) recording was finalised, still readable as 0 frames
    assert assert_recording(tmp_path / "denied.dat", frames_none())["device_bytes_in"] == 0
    cam.close()


def frames_none() -> np.ndarray:
    return np.zeros((0, 1000, 1000), np.uint8)


def test_no_usb_backend_says_to_install_libusb(monkeypatch):
    def no_backend(*args, **kwargs):
        raise usb.core.NoBackendError("No backend available")

    monkeypatch.setattr(usb.core, "find", no_backend)
    cam = UsbCamera(CameraConfig(vid=1, pid=2)).start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.NO_BACKEND and "libusb" in cam.status_message
    cam.close()


def test_busy_interface_is_an_error_not_a_crash(monkeypatch, raw):
    be = MockBackend([raw])

    def busy(handle, intf):
        raise usb.core.USBError("Resource busy", -6, errno.EBUSY)

    monkeypatch.setattr(be, "claim_interface", busy)
    cam = camera(be).start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.ERROR and "in use by another program" in cam.status_message
    cam.close()


def test_wrong_endpoint_lists_the_ones_there():
    cam = camera(MockBackend(), endpoint=0x82).start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.ERROR and "0x81" in cam.status_message
    cam.close()


# ------------------------------------------------------------------------------------- closing while recording


def test_closing_during_a_recording_leaves_a_complete_file(tmp_path, frames, raw):
    def endless():
        while True:
            yield raw

    cam = camera(MockBackend(endless(), max_read=50_000))
    path = tmp_path / "closed.dat"
    cam.start_recording(path)
    cam.start()
    assert cam.wait_frames(20, WAIT_S)
    cam.close(timeout=WAIT_S)
    assert cam.status is LiveStatus.STOPPED and not cam.running
    table = read_sidecar(path).tables["recording"]
    n = table["frames"]
    assert n >= 20 and n == cam.n_frames  # every frame acquired is on disk
    assert_recording(path, frames[np.arange(n) % T])


def test_stop_recording_while_streaming_keeps_a_contiguous_range(tmp_path, frames, raw):
    def endless():
        while True:
            yield raw

    cam = camera(MockBackend(endless())).start()
    assert cam.wait_frames(3, WAIT_S)
    rec = cam.start_recording(tmp_path / "mid.dat")
    with pytest.raises(ParameterError, match="already recording"):
        cam.start_recording(tmp_path / "again.dat")
    assert cam.wait_frames(cam.n_frames + 10, WAIT_S)
    summary = cam.stop_recording(timeout=WAIT_S)
    cam.close(timeout=WAIT_S)
    assert summary.state == "done" and summary.frames >= 10
    first = read_sidecar(rec.path).tables["recording"]["first_tick"]
    assert_recording(rec.path, frames[(first + np.arange(summary.frames)) % T])


def test_recording_never_overwrites_without_asking(tmp_path):
    path = tmp_path / "taken.dat"
    path.write_bytes(b"keep me")
    cam = camera(MockBackend())
    with pytest.raises(OutputFileError, match="exists"):
        cam.start_recording(path)
    assert path.read_bytes() == b"keep me"
    cam.close()


# ------------------------------------------------------------------------------------- formats, ROI


def test_roi_and_decimation_on_a_colour_camera(tmp_path, frames, raw):
    cam = camera(MockBackend([raw], then="disconnect"), roi=[100, 200, 64, 128], decimate=2, cfa="RGGB", frame_step=2)
    assert (cam.width, cam.height, cam.tick_rate, cam.cfa) == (64, 32, 10_000.0, "RGGB")
    run_recorded(cam, tmp_path / "roi.dat")
    cells = np.arange(64)
    rows = 100 + cells[(cells // 2) % 2 == 0]
    cols = 200 + np.arange(128)[(np.arange(128) // 2) % 2 == 0]
    expected = frames[::2][:, rows][:, :, cols]
    assert_recording(tmp_path / "roi.dat", expected)
    with open_source(tmp_path / "roi.dat") as src:
        assert (src.cfa, src.tick_rate) == ("RGGB", 10_000.0)


def test_plain_camera_stream(tmp_path):
    rng = np.random.default_rng(11)
    x = rng.integers(0, 2, (6, 32, 48), dtype=np.uint8)
    data = pack_frames(x, flip_vertical=True).tobytes()  # what a plain camera sends (rows stored upside down)
    cam = camera(MockBackend([data[:1000], data[1000:]], then="disconnect"), format="plain", width=48, height=32)
    assert cam.info.flip_vertical
    run_recorded(cam, tmp_path / "plain.dat")
    np.testing.assert_array_equal(cam.read(0, 6), x)
    assert (tmp_path / "plain.dat").read_bytes() == data
    with open_source(tmp_path / "plain.dat") as src:
        np.testing.assert_array_equal(src.read(0, 6), x)


# ------------------------------------------------------------------------------------- settings


def test_camera_config_round_trips_through_toml(tmp_path):
    cfg = CameraConfig(vid=0x1234, pid=0xABCD, format="plain", width=400, height=250, cfa="BGGR",
                       roi=[0, 0, 200, 400], decimate=1, flip_vertical=True)
    loaded = CameraConfig.load(cfg.save(tmp_path / "camera.toml"))
    assert loaded == cfg


@pytest.mark.parametrize("settings, match", [
    ({"format": "plain"}, "needs width and height"),
    ({"format": "mp4"}, "raw1m"),
    ({"transfer_bytes": 1000}, "multiple of 1024"),
    ({"endpoint": 0x01}, "not an IN endpoint"),
    ({"vid": 0x10000}, "16-bit"),
    ({"roi": [1, 0, 100, 100], "cfa": "RGGB"}, "even"),
])
def test_camera_config_errors_say_the_fix(settings, match):
    with pytest.raises(ParameterError, match=match):
        CameraConfig(**settings)
