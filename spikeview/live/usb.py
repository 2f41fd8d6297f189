"""The USB spike camera, through pyusb: find it, claim it, read its bulk endpoint, decode.

:class:`UsbCamera` is a :class:`~spikeview.live.source.LiveSource`. Its acquisition thread reads the
bulk IN endpoint in large transfers (``transfer_bytes``, 2 MiB by default: about 16 raw
1000×1000 frames, a few hundred transfers per second at USB 3 rates) into one reused buffer, and
decodes them (:mod:`spikeview.live.decode`): the tagged raw 1000×1000 stream (resynchronised
after corruption, dropped frames counted) or plain packed frames.

Everything a device can do wrong ends as a status with a sentence that says what to do
(:class:`~spikeview.live.source.LiveStatus`), never as an exception out of the thread:

========================  ==================================================================
no libusb                 ``NO_BACKEND``: install libusb 1.0
no such device            ``NOT_FOUND``: plug it in, check vid/pid against ``lsusb``
access refused            ``PERMISSION_DENIED``: the udev rule to add (:func:`udev_rule`)
no data                   ``WAITING`` after each timeout, ``TIMEOUT`` after ``max_timeouts``
                          in a row
endpoint stall            cleared and retried; ``PIPE_ERROR`` after ``max_pipe_errors`` in a row
unplugged                 ``DISCONNECTED``
========================  ==================================================================

**Bandwidth.** The sensor produces 2.5 GB/s; USB 3 carries about 400 MB/s in practice. The
camera must therefore send less (a region, fewer frames); the command that tells it to is
vendor-specific and not public, so spikeview does not send any command to the device: it reads
what the camera streams. ``roi``/``decimate``/``frame_step`` are applied on the host after
decoding (see :mod:`spikeview.live.decode`).

pyusb picks its backend itself (libusb 1.0 normally); tests pass a mock backend
(:mod:`spikeview.live.mockusb`).
"""

from __future__ import annotations

import array
import errno
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from spikeview.cfa import cfa_to_str, parse_cfa
from spikeview.config import Config
from spikeview.errors import ParameterError
from spikeview.io.raw1m import RAW1M_HEIGHT, RAW1M_WIDTH, TAG_CHECKS
from spikeview.io.source import DEFAULT_TICK_RATE
from spikeview.live.decode import FrameShaper, PlainStream, Raw1MStream
from spikeview.live.source import DEFAULT_RING_MB, LiveFailure, LiveSource, LiveStatus, StatusCallback

#: formats a camera may stream
CAMERA_FORMATS = ("raw1m", "plain")
#: USB 3 bulk endpoints move 1024-byte packets; transfers should be whole packets
_PACKET = 1024



def parse_hex_id(text: str, name: str) -> int | None:
    """A USB id or endpoint as typed (``1234``, ``0x81``; hexadecimal), ``None`` when empty.

    Raises:
        ParameterError: not a hexadecimal number (one sentence naming ``name``).
    """
    t = str(text).strip().lower().removeprefix("0x")
    if not t:
        return None
    try:
        return int(t, 16)
    except ValueError:
        raise ParameterError(f"{name} {text!r} is not a hexadecimal number; copy it from 'lsusb' (e.g. 1234).") from None


def parse_roi(text: str) -> list[int] | None:
    """A camera ROI as typed (``top, left, height, width``; commas or spaces), ``None`` when empty.

    Raises:
        ParameterError: not whole numbers.
    """
    t = str(text).strip()
    if not t:
        return None
    try:
        return [int(v) for v in t.replace(",", " ").split()]
    except ValueError:
        raise ParameterError(f"ROI {t!r} is not four whole numbers; write top, left, height, width.") from None


@dataclass
class CameraConfig(Config):
    """How to find, read and decode a USB spike camera; saves to TOML and loads back unchanged.

    Device:
        vid, pid: USB vendor and product id (as ``lsusb`` shows them, e.g. ``0x1234``). Required:
            the camera vendors' ids are not public.
        bus, address: pick one of several identical cameras (``None``: the first found).
        interface: interface number to claim.
        alt_setting: alternate setting to select (``None``: leave the default).
        endpoint: bulk IN endpoint address (``0x81`` = endpoint 1, IN).
        transfer_bytes: bytes per bulk read, a multiple of 1024 (bigger transfers, fewer calls).
        timeout_ms: how long one read waits for data.
        max_timeouts: give up (``TIMEOUT``) after this many timeouts in a row; 0 waits forever.
        max_pipe_errors: give up (``PIPE_ERROR``) after this many endpoint stalls in a row (each
            is cleared and retried); 0 gives up at the first.

    Stream:
        format: ``"raw1m"`` (tagged 1000×1000) or ``"plain"`` (packed frames, no tags).
        width, height: frame size of a ``plain`` stream (``raw1m`` is always 1000×1000).
        tag_check: ``"sequence"`` or ``"lenient"`` (raw1m; see :class:`~spikeview.io.raw1m.Raw1MSource`).
        flip_vertical, flip_horizontal: flips from the sensor's row order to display
            orientation (``None``: the format's default, no flip for raw1m, vertical flip for
            plain, as for files).
        cfa: top-left 2×2 of the displayed (flipped, cropped) frame, or ``"none"``.
        tick_rate: sensor readouts per second (Hz).

    Host-side reduction (after decoding; see the module docstring):
        roi: ``[top, left, height, width]`` in sensor pixels (before flips), or ``None``.
        decimate: keep every n-th pixel (every n-th 2×2 cell on colour sensors).
        frame_step: keep every n-th frame.

    Buffers:
        ring_mb: ring buffer for the display and readers (MiB).
        record_queue_mb: bound of the recorder's queue when the disk falls behind (MiB).
    """

    vid: int | None = None
    pid: int | None = None
    bus: int | None = None
    address: int | None = None
    interface: int = 0
    alt_setting: int | None = None
    endpoint: int = 0x81
    transfer_bytes: int = 2 << 20
    timeout_ms: int = 1000
    max_timeouts: int = 10
    max_pipe_errors: int = 3

    format: str = "raw1m"
    width: int | None = None
    height: int | None = None
    tag_check: str = "sequence"
    flip_vertical: bool | None = None
    flip_horizontal: bool = False
    cfa: str = "none"
    tick_rate: float = DEFAULT_TICK_RATE

    roi: list[int] | None = None
    decimate: int = 1
    frame_step: int = 1

    ring_mb: float = float(DEFAULT_RING_MB)
    record_queue_mb: float = 2048.0

    def __post_init__(self) -> None:
        for name in ("vid", "pid"):
            v = getattr(self, name)
            if v is not None and not (0 <= v <= 0xFFFF):
                raise ParameterError(f"{name} must be a 16-bit USB id (0x0000-0xffff), got {v}; copy it from 'lsusb'.")
        if self.format not in CAMERA_FORMATS:
            raise ParameterError(f"camera format {self.format!r} is unknown: use 'raw1m' or 'plain'.")
        if self.tag_check not in TAG_CHECKS:
            raise ParameterError(f"tag_check {self.tag_check!r} is unknown: use 'sequence' or 'lenient'.")
        if not (self.endpoint & 0x80) or not (0 <= self.endpoint <= 0xFF):
            raise ParameterError(f"endpoint 0x{self.endpoint:x} is not an IN endpoint; IN endpoint addresses have bit 7 "
                                 f"set (e.g. 0x81).")
        if self.transfer_bytes < _PACKET or self.transfer_bytes % _PACKET:
            raise ParameterError(f"transfer_bytes must be a positive multiple of {_PACKET} (whole USB packets), got "
                                 f"{self.transfer_bytes}; e.g. 2097152.")
        if self.timeout_ms < 1:
            raise ParameterError(f"timeout_ms must be at least 1, got {self.timeout_ms}; e.g. 1000.")
        if self.max_timeouts < 0 or self.max_pipe_errors < 0:
            raise ParameterError("max_timeouts and max_pipe_errors must be ≥ 0; use 0 for 'never retry'/'wait forever'.")
        if not (math.isfinite(self.tick_rate) and self.tick_rate > 0):
            raise ParameterError(f"tick_rate must be a positive number of readouts per second, got {self.tick_rate}.")
        if self.format == "plain":
            if self.width is None or self.height is None:
                raise ParameterError("a plain camera stream needs width and height (the frames carry no header); "
                                     "set both in the camera settings.")
            if self.width < 1 or self.height < 1:
                raise ParameterError(f"width and height must be positive, got {self.width}x{self.height}.")
        self.cfa = cfa_to_str(parse_cfa(self.cfa))
        if not (self.ring_mb > 0 and self.record_queue_mb > 0):
            raise ParameterError("ring_mb and record_queue_mb must be positive numbers of MiB; e.g. 256 and 2048.")
        self.shaper()  # validates roi/decimate/frame_step against the geometry

    # --- derived ---------------------------------------------------------------------------
    @property
    def sensor_size(self) -> tuple[int, int]:
        """``(height, width)`` of a decoded frame before ROI/decimation."""
        if self.format == "raw1m":
            return RAW1M_HEIGHT, RAW1M_WIDTH
        return int(self.height), int(self.width)  # type: ignore[arg-type]

    @property
    def flips(self) -> tuple[bool, bool]:
        """``(flip_vertical, flip_horizontal)`` with the format's default filled in."""
        fv = self.flip_vertical if self.flip_vertical is not None else self.format == "plain"
        return bool(fv), bool(self.flip_horizontal)

    def shaper(self) -> FrameShaper:
        """A fresh :class:`~spikeview.live.decode.FrameShaper` for these settings."""
        h, w = self.sensor_size
        return FrameShaper(h, w, roi=self.roi, decimate=self.decimate, frame_step=self.frame_step,
                           colour=parse_cfa(self.cfa) is not None)

    @property
    def device_id(self) -> str:
        """``"1234:5678"`` (or ``"?:?"`` while unset)."""
        v = "?" if self.vid is None else f"{self.vid:04x}"
        p = "?" if self.pid is None else f"{self.pid:04x}"
        return f"{v}:{p}"


def udev_rule(vid: int | None, pid: int | None) -> str:
    """The udev rule line that lets every user open the camera (for ``/etc/udev/rules.d/99-spikeview.rules``)."""
    v = "????" if vid is None else f"{vid:04x}"
    p = "????" if pid is None else f"{pid:04x}"
    return f'SUBSYSTEM=="usb", ATTRS{{idVendor}}=="{v}", ATTRS{{idProduct}}=="{p}", MODE="0666"'


def permission_message(vid: int | None, pid: int | None) -> str:
    """The sentence shown when the OS refuses access to the camera."""
    v = "????" if vid is None else f"{vid:04x}"
    p = "????" if pid is None else f"{pid:04x}"
    return (f"Permission denied opening USB device {v}:{p}: add the line '{udev_rule(vid, pid)}' to "
            f"/etc/udev/rules.d/99-spikeview.rules, run 'sudo udevadm control --reload-rules && sudo udevadm trigger', "
            f"and plug the camera in again.")


NO_BACKEND_MESSAGE = ("No USB backend found (pyusb needs libusb): install libusb 1.0 (e.g. 'sudo apt install libusb-1.0-0', "
                      "'brew install libusb' or 'conda install libusb') and try again.")


@dataclass
class UsbDeviceInfo:
    """One USB device found by :func:`list_usb_devices`."""

    vid: int
    pid: int
    bus: int | None
    address: int | None
    manufacturer: str | None = None
    product: str | None = None

    @property
    def label(self) -> str:
        name = " ".join(s for s in (self.manufacturer, self.product) if s) or "USB device"
        where = f" (bus {self.bus}, address {self.address})" if self.bus is not None else ""
        return f"{name} {self.vid:04x}:{self.pid:04x}{where}"


def list_usb_devices(backend: Any = None, *, vid: int | None = None, pid: int | None = None) -> list[UsbDeviceInfo]:
    """USB devices pyusb can see (optionally only ``vid``/``pid``), with names where readable.

    Raises:
        SpikeviewError: no USB backend (the message says how to install libusb).
    """
    import usb.core
    import usb.util

    from spikeview.errors import SpikeviewError

    match: dict[str, int] = {}
    if vid is not None:
        match["idVendor"] = vid
    if pid is not None:
        match["idProduct"] = pid
    try:
        devices = list(usb.core.find(find_all=True, backend=backend, **match))
    except usb.core.NoBackendError:
        raise SpikeviewError(NO_BACKEND_MESSAGE) from None
    out = []
    for d in devices:
        names: list[str | None] = []
        for index in (d.iManufacturer, d.iProduct):
            try:  # needs access to the device: without permission the names stay unknown
                names.append(usb.util.get_string(d, index) if index else None)
            except Exception:
                names.append(None)
        out.append(UsbDeviceInfo(int(d.idVendor), int(d.idProduct), d.bus, d.address, names[0], names[1]))
        usb.util.dispose_resources(d)
    return out


def _errno_of(e: BaseException) -> int | None:
    return getattr(e, "errno", None)


class UsbCamera(LiveSource):
    """A USB spike camera read through pyusb (see the module docstring).

    Args:
        config: the :class:`CameraConfig`.
        backend: a pyusb backend (``None``: pyusb's default, libusb 1.0); tests pass
            :class:`~spikeview.live.mockusb.MockBackend`.
        label: name for people (default ``"USB camera vid:pid"``).
        on_status: status callback (see :class:`~spikeview.live.source.LiveSource`).

    Call :meth:`start`; watch :attr:`status`/:attr:`status_message`; read with ``read``/``latest``;
    record with :meth:`start_recording`; :meth:`close` when done.
    """

    def __init__(self, config: CameraConfig, *, backend: Any = None, label: str | None = None,
                 on_status: StatusCallback | None = None):
        self.config = config
        self.backend = backend
        shaper = config.shaper()
        fv, fh = config.flips
        cfg_extra = {"device": config.device_id, "format": config.format, "endpoint": config.endpoint,
                     **shaper.settings()}
        super().__init__(width=shaper.out_width, height=shaper.out_height, flip_vertical=fv, flip_horizontal=fh,
                         cfa=config.cfa, tick_rate=config.tick_rate / shaper.frame_step,
                         label=label or f"USB camera {config.device_id}", ring_mb=config.ring_mb,
                         record_queue_mb=config.record_queue_mb, extra=cfg_extra, on_status=on_status)
        self.decoder: Raw1MStream | PlainStream = (Raw1MStream(shaper, config.tag_check) if config.format == "raw1m"
                                                   else PlainStream(shaper))
        self._dev: Any = None
        self._claimed = False
        self._buf = array.array("B", bytes(config.transfer_bytes))
        self._timeouts = 0
        self._pipe_errors = 0
        self._timeouts_in_row = 0
        self._pipe_in_row = 0
        self._got_data = False

    # ------------------------------------------------------------------------------ opening
    def _open(self) -> None:
        import usb.core
        import usb.util

        c = self.config
        if c.vid is None or c.pid is None:
            raise LiveFailure(LiveStatus.NOT_FOUND, "No camera chosen: set the camera's vendor and product id (vid, pid; "
                                                    "'lsusb' lists them) or pick it in Open camera.")
        match: dict[str, Any] = {"idVendor": c.vid, "idProduct": c.pid}
        if c.bus is not None:
            match["bus"] = c.bus
        if c.address is not None:
            match["address"] = c.address
        try:
            dev = usb.core.find(backend=self.backend, **match)
        except usb.core.NoBackendError:
            raise LiveFailure(LiveStatus.NO_BACKEND, NO_BACKEND_MESSAGE) from None
        except usb.core.USBError as e:
            raise self._failure(e, "looking for the camera") from None
        if dev is None:
            where = "" if c.bus is None else f" on bus {c.bus}" + ("" if c.address is None else f", address {c.address}")
            raise LiveFailure(LiveStatus.NOT_FOUND, f"No USB device {c.device_id}{where} found: check that the camera is "
                                                    f"plugged in and powered, and that vid/pid match what 'lsusb' shows.")
        self._dev = dev
        try:
            try:
                dev.get_active_configuration()
            except usb.core.USBError as e:
                if _errno_of(e) in (errno.EACCES, errno.EPERM):
                    raise
                dev.set_configuration()
            try:
                if dev.is_kernel_driver_active(c.interface):
                    dev.detach_kernel_driver(c.interface)
            except (NotImplementedError, usb.core.USBError):
                pass  # not supported on this platform/backend, or no driver attached
            if c.alt_setting is not None:
                dev.set_interface_altsetting(interface=c.interface, alternate_setting=c.alt_setting)
            usb.util.claim_interface(dev, c.interface)
            self._claimed = True
            self._check_endpoint(dev)
        except usb.core.USBError as e:
            raise self._failure(e, "opening the camera") from None
        except ValueError as e:  # pyusb: no such configuration/interface/endpoint
            raise LiveFailure(LiveStatus.ERROR, f"USB camera {c.device_id}: {e}; check interface "
                                                f"{c.interface} and endpoint 0x{c.endpoint:02x} in the camera settings.") from None

    def _check_endpoint(self, dev: Any) -> None:
        import usb.util

        c = self.config
        cfg = dev.get_active_configuration()
        intf = usb.util.find_descriptor(cfg, bInterfaceNumber=c.interface,
                                        bAlternateSetting=c.alt_setting if c.alt_setting is not None else 0)
        if intf is None:
            found = sorted({i.bInterfaceNumber for i in cfg})
            raise LiveFailure(LiveStatus.ERROR, f"USB camera {c.device_id} has no interface {c.interface} (it has "
                                                f"{found}); set interface in the camera settings.")
        ep = usb.util.find_descriptor(intf, bEndpointAddress=c.endpoint)
        eps = [f"0x{e.bEndpointAddress:02x}" for e in intf]
        if ep is None:
            raise LiveFailure(LiveStatus.ERROR, f"USB camera {c.device_id}, interface {c.interface}, has no endpoint "
                                                f"0x{c.endpoint:02x} (it has {', '.join(eps) or 'none'}); set endpoint in "
                                                f"the camera settings.")
        if usb.util.endpoint_type(ep.bmAttributes) != usb.util.ENDPOINT_TYPE_BULK:
            raise LiveFailure(LiveStatus.ERROR, f"Endpoint 0x{c.endpoint:02x} of USB camera {c.device_id} is not a bulk "
                                                f"endpoint; choose the camera's bulk IN endpoint (one of {', '.join(eps)}).")
        mps = int(ep.wMaxPacketSize) & 0x7FF
        if mps and c.transfer_bytes % mps:
            raise LiveFailure(LiveStatus.ERROR, f"transfer_bytes {c.transfer_bytes} is not a multiple of endpoint "
                                                f"0x{c.endpoint:02x}'s packet size {mps}; use a multiple of {mps}.")

    def _failure(self, e: BaseException, doing: str) -> LiveFailure:
        """Map a pyusb error to a status and a sentence."""
        import usb.core

        c = self.config
        code = _errno_of(e)
        name = f"USB camera {c.device_id}"
        if isinstance(e, usb.core.USBTimeoutError) or code == errno.ETIMEDOUT:
            return LiveFailure(LiveStatus.TIMEOUT, f"{name} sent no data for {c.timeout_ms * max(self._timeouts_in_row, 1) / 1000:g} s: "
                                                   f"check that it is streaming (some cameras need their vendor software "
                                                   f"to start) and that endpoint 0x{c.endpoint:02x} is right.")
        if code in (errno.EACCES, errno.EPERM):
            return LiveFailure(LiveStatus.PERMISSION_DENIED, permission_message(c.vid, c.pid))
        if code == errno.EPIPE:
            return LiveFailure(LiveStatus.PIPE_ERROR, f"{name}: endpoint 0x{c.endpoint:02x} stalled (pipe error) "
                                                      f"{self._pipe_in_row} time(s) in a row while {doing}: unplug the "
                                                      f"camera, plug it in again and reopen it.")
        if code in (errno.ENODEV, errno.ENXIO, errno.ESHUTDOWN, errno.ENOENT):
            return LiveFailure(LiveStatus.DISCONNECTED, f"{name} was disconnected while {doing} (after "
                                                        f"{self.info.n_frames} frames): plug it in again and reopen it.")
        if code == errno.EBUSY:
            return LiveFailure(LiveStatus.ERROR, f"{name}: interface {c.interface} is in use by another program or "
                                                 f"driver; close the other program (e.g. the vendor's viewer) and reopen.")
        if code == errno.EOVERFLOW:
            return LiveFailure(LiveStatus.ERROR, f"{name}: a transfer overflowed; make transfer_bytes a multiple of the "
                                                 f"endpoint's packet size (1024 on USB 3).")
        if code == errno.EIO:
            return LiveFailure(LiveStatus.DISCONNECTED, f"{name}: USB I/O error while {doing} (the camera was unplugged "
                                                        f"or the cable/port is faulty): check the cable and reopen it.")
        return LiveFailure(LiveStatus.ERROR, f"{name}: USB error while {doing} ({e}); unplug and replug the camera and "
                                             f"reopen it.")

    # ------------------------------------------------------------------------------ reading
    def _next(self) -> np.ndarray:
        import usb.core

        c = self.config
        try:
            n = self._dev.read(c.endpoint, self._buf, c.timeout_ms)
        except usb.core.USBError as e:
            if isinstance(e, usb.core.USBTimeoutError) or _errno_of(e) == errno.ETIMEDOUT:
                self._timeouts += 1
                self._timeouts_in_row += 1
                if c.max_timeouts and self._timeouts_in_row >= c.max_timeouts:
                    raise self._failure(e, "reading") from None
                waited = self._timeouts_in_row * c.timeout_ms / 1000
                self._set_status(LiveStatus.WAITING, f"{self.label}: no data for {waited:g} s; waiting (check that the "
                                                     f"camera is streaming).")
                return self._empty()
            if _errno_of(e) == errno.EPIPE:
                self._pipe_errors += 1
                self._pipe_in_row += 1
                if self._pipe_in_row > c.max_pipe_errors:
                    raise self._failure(e, "reading") from None
                try:
                    self._dev.clear_halt(c.endpoint)
                except usb.core.USBError as e2:
                    raise self._failure(e2, "clearing the stalled endpoint") from None
                return self._empty()
            raise self._failure(e, "reading") from None
        self._timeouts_in_row = 0
        self._pipe_in_row = 0
        if n <= 0:
            return self._empty()
        if not self._got_data or self._status is not LiveStatus.RUNNING:
            self._got_data = True
            self._set_status(LiveStatus.RUNNING, f"{self.label}: streaming.")
        return self.decoder.feed(memoryview(self._buf)[:n])

    def _empty(self) -> np.ndarray:
        return np.zeros((0, self.frame_bytes), dtype=np.uint8)

    def _close_device(self) -> None:
        import usb.util

        dev, self._dev = self._dev, None
        if dev is None:
            return
        try:
            if self._claimed:
                usb.util.release_interface(dev, self.config.interface)
        except Exception:  # the device may be gone already
            pass
        try:
            usb.util.dispose_resources(dev)
        except Exception:
            pass

    def _finish_stream(self) -> None:
        self.decoder.finish()

    def device_counters(self) -> dict[str, int]:
        s = self.decoder.stats
        return {"dropped_frames": s.skipped_frames, "skipped_bytes": s.skipped_bytes, "resyncs": s.resyncs,
                "leading_bytes": s.leading_bytes, "trailing_bytes": s.trailing_bytes, "decoded_frames": s.frames,
                "timeouts": self._timeouts, "pipe_errors": self._pipe_errors, "bytes_in": self.decoder.bytes_in}
