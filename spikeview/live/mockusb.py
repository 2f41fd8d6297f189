"""A mock pyusb backend that plays a scripted spike camera: for tests, the benchmark and demos.

:class:`MockBackend` is a real :class:`usb.backend.IBackend`: pass it to ``usb.core.find(backend=...)``
(or to :class:`~spikeview.live.usb.UsbCamera` as ``backend=``) and pyusb's own device, configuration,
interface and endpoint objects are built on it, so the camera code runs exactly as it does on
libusb. The device has one configuration, one interface (0) and one bulk IN endpoint (0x81,
1024-byte packets), and answers string-descriptor requests (manufacturer, product).

Its bulk endpoint serves a **script**, item by item (any iterable, so a generator can stream an
endless capture):

* bytes-like items (``bytes``, ``bytearray``, ``memoryview``, uint8 arrays): data, served in
  reads of at most the reader's buffer (and ``max_read``); a read never spans two items, as a
  short USB packet ends a transfer;
* :class:`Fault` items: raise what libusb would raise once the data before them is read —
  ``Fault("timeout")`` (:class:`usb.core.USBTimeoutError`), ``Fault("pipe")`` (an endpoint stall,
  errno ``EPIPE``, cleared by ``clear_halt``), ``Fault("disconnect")`` (errno ``ENODEV``; the device
  is gone for good: every later call fails and it is no longer listed), ``Fault("io")`` (``EIO``).

After the script, reads time out (``then="timeout"``, a camera that stopped streaming) or the
device disconnects (``then="disconnect"``). ``open_error="access"`` makes opening fail like a
device without a udev rule (``EACCES``). Counters (``sent_bytes``, ``reads``, ``clear_halts`` …)
let tests check what really went over the "wire".
"""

from __future__ import annotations

import errno
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import usb.backend
import usb.core

#: default ids of the mock camera (0xf055 is a vendor id reserved for open-source projects' tests)
MOCK_VID = 0xF055
MOCK_PID = 0x5B1C
_LIBUSB_NO_DEVICE = -4
_LIBUSB_TIMEOUT = -7
_LIBUSB_PIPE = -9
_LIBUSB_ACCESS = -3
_LIBUSB_IO = -1


@dataclass(frozen=True)
class Fault:
    """A scripted fault: ``"timeout"``, ``"pipe"``, ``"disconnect"`` or ``"io"``."""

    kind: str

    def __post_init__(self) -> None:
        if self.kind not in ("timeout", "pipe", "disconnect", "io"):
            raise ValueError(f"unknown fault {self.kind!r}: use timeout, pipe, disconnect or io")


class _Desc:
    """A descriptor: an object with attributes (what pyusb reads from backends)."""

    def __init__(self, **fields: Any):
        self.__dict__.update(fields)


class _Handle:
    def __init__(self, dev: "_Desc"):
        self.dev = dev


class MockBackend(usb.backend.IBackend):
    """A scripted USB spike camera (see the module docstring).

    Args:
        script: the items the bulk endpoint serves, in order.
        vid, pid: device ids.
        then: after the script, ``"timeout"`` or ``"disconnect"``.
        open_error: ``None`` or ``"access"`` (opening the device is refused, like a missing udev rule).
        max_read: most bytes one read returns (emulates short transfers); ``None``: the buffer size.
        manufacturer, product: the string descriptors.
        bus, address: where the device sits.
        configured: the device starts configured (otherwise the host must set configuration 1).
    """

    def __init__(self, script: Iterable[Any] = (), *, vid: int = MOCK_VID, pid: int = MOCK_PID, then: str = "timeout",
                 open_error: str | None = None, max_read: int | None = None, manufacturer: str = "spikeview",
                 product: str = "Mock spike camera", bus: int = 1, address: int = 7, configured: bool = False):
        if then not in ("timeout", "disconnect"):
            raise ValueError(f"then must be 'timeout' or 'disconnect', got {then!r}")
        self._items: Iterator[Any] = iter(script)
        self._current: memoryview | None = None
        self._pos = 0
        self.then = then
        self.open_error = open_error
        self.max_read = max_read
        self.strings = {1: manufacturer, 2: product}
        self.connected = True
        self.configuration = 1 if configured else 0
        self.lock = threading.Lock()
        # counters
        self.sent_bytes = 0
        self.reads = 0
        self.timeouts = 0
        self.clear_halts = 0
        self.claimed: set[int] = set()
        self.opened = 0
        self.closed = 0
        self.stalled = False
        self.device = _Desc(
            bLength=18, bDescriptorType=1, bcdUSB=0x0320, bDeviceClass=0xFF, bDeviceSubClass=0, bDeviceProtocol=0,
            bMaxPacketSize0=9, idVendor=vid, idProduct=pid, bcdDevice=0x0100, iManufacturer=1, iProduct=2,
            iSerialNumber=0, bNumConfigurations=1, address=address, bus=bus, port_number=1, port_numbers=(1,), speed=4)

    # ---------------------------------------------------------------------------- descriptors
    def enumerate_devices(self) -> Iterator[Any]:
        if self.connected:
            yield self.device

    def get_parent(self, dev: Any) -> Any:
        return None

    def get_device_descriptor(self, dev: Any) -> Any:
        return dev

    def get_configuration_descriptor(self, dev: Any, config: int) -> Any:
        if config != 0:
            raise IndexError("no such configuration")
        return _Desc(bLength=9, bDescriptorType=2, wTotalLength=32, bNumInterfaces=1, bConfigurationValue=1,
                     iConfiguration=0, bmAttributes=0x80, bMaxPower=250, extra_descriptors=[])

    def get_interface_descriptor(self, dev: Any, intf: int, alt: int, config: int) -> Any:
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError("no such interface")
        return _Desc(bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0, bNumEndpoints=1,
                     bInterfaceClass=0xFF, bInterfaceSubClass=0, bInterfaceProtocol=0, iInterface=0, extra_descriptors=[])

    def get_endpoint_descriptor(self, dev: Any, ep: int, intf: int, alt: int, config: int) -> Any:
        if (ep, intf, alt, config) != (0, 0, 0, 0):
            raise IndexError("no such endpoint")
        return _Desc(bLength=7, bDescriptorType=5, bEndpointAddress=0x81, bmAttributes=0x02, wMaxPacketSize=1024,
                     bInterval=0, bRefresh=0, bSynchAddress=0, extra_descriptors=[])

    # ---------------------------------------------------------------------------- device handle
    def _check(self) -> None:
        if not self.connected:
            raise usb.core.USBError("No such device (it may have been disconnected)", _LIBUSB_NO_DEVICE, errno.ENODEV)

    def open_device(self, dev: Any) -> Any:
        self._check()
        if self.open_error == "access":
            raise usb.core.USBError("Access denied (insufficient permissions)", _LIBUSB_ACCESS, errno.EACCES)
        self.opened += 1
        return _Handle(dev)

    def close_device(self, dev_handle: Any) -> None:
        self.closed += 1

    def set_configuration(self, dev_handle: Any, config_value: int) -> None:
        self._check()
        self.configuration = config_value

    def get_configuration(self, dev_handle: Any) -> int:
        self._check()
        return self.configuration

    def set_interface_altsetting(self, dev_handle: Any, intf: int, altsetting: int) -> None:
        self._check()

    def claim_interface(self, dev_handle: Any, intf: int) -> None:
        self._check()
        self.claimed.add(intf)

    def release_interface(self, dev_handle: Any, intf: int) -> None:
        self._check()
        self.claimed.discard(intf)

    def is_kernel_driver_active(self, dev_handle: Any, intf: int) -> bool:
        self._check()
        return False

    def detach_kernel_driver(self, dev_handle: Any, intf: int) -> None:
        self._check()

    def attach_kernel_driver(self, dev_handle: Any, intf: int) -> None:
        self._check()

    def clear_halt(self, dev_handle: Any, ep: int) -> None:
        self._check()
        self.clear_halts += 1
        self.stalled = False

    def reset_device(self, dev_handle: Any) -> None:
        self._check()

    def ctrl_transfer(self, dev_handle: Any, bmRequestType: int, bRequest: int, wValue: int, wIndex: int, data: Any,
                      timeout: int) -> int:
        self._check()
        if bmRequestType == 0x80 and bRequest == 6 and (wValue >> 8) == 3:  # GET_DESCRIPTOR(STRING)
            index = wValue & 0xFF
            if index == 0:
                payload = bytes([4, 3, 0x09, 0x04])  # one language: en-US
            else:
                text = self.strings.get(index, "").encode("utf-16-le")
                payload = bytes([2 + len(text), 3]) + text
            k = min(len(payload), len(data))
            data[:k] = type(data)("B", payload[:k])
            return k
        raise usb.core.USBError("Pipe error (request not supported)", _LIBUSB_PIPE, errno.EPIPE)

    # ---------------------------------------------------------------------------- bulk endpoint
    def _next_item(self) -> Any:
        try:
            return next(self._items)
        except StopIteration:
            return Fault("disconnect") if self.then == "disconnect" else Fault("timeout")

    def _raise(self, fault: Fault) -> None:
        if fault.kind == "timeout":
            self.timeouts += 1
            raise usb.core.USBTimeoutError("Operation timed out", _LIBUSB_TIMEOUT, errno.ETIMEDOUT)
        if fault.kind == "pipe":
            self.stalled = True
            raise usb.core.USBError("Pipe error", _LIBUSB_PIPE, errno.EPIPE)
        if fault.kind == "io":
            raise usb.core.USBError("Input/Output Error", _LIBUSB_IO, errno.EIO)
        self.connected = False
        raise usb.core.USBError("No such device (it may have been disconnected)", _LIBUSB_NO_DEVICE, errno.ENODEV)

    def bulk_read(self, dev_handle: Any, ep: int, intf: int, buff: Any, timeout: int) -> int:
        with self.lock:
            self._check()
            self.reads += 1
            if self.stalled:
                raise usb.core.USBError("Pipe error", _LIBUSB_PIPE, errno.EPIPE)
            while self._current is None:
                item = self._next_item()
                if isinstance(item, Fault):
                    self._raise(item)
                view = memoryview(np.ascontiguousarray(item).reshape(-1) if isinstance(item, np.ndarray) else item).cast("B")
                if len(view):
                    self._current, self._pos = view, 0
            out = memoryview(buff).cast("B")
            k = min(len(out), len(self._current) - self._pos)
            if self.max_read is not None:
                k = min(k, self.max_read)
            out[:k] = self._current[self._pos:self._pos + k]
            self._pos += k
            if self._pos >= len(self._current):
                self._current = None
            self.sent_bytes += k
            return k

    def bulk_write(self, dev_handle: Any, ep: int, intf: int, data: Any, timeout: int) -> int:
        self._check()
        return len(data)
