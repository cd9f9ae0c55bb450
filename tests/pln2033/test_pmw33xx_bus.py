"""SpidevBus.xfer_segments without hardware: the SPI_IOC_MESSAGE(n) encoding and struct layout
against linux/spi/spidev.h, and what the ioctls carry (a loopback fake of the kernel)."""

from __future__ import annotations

import ctypes
import fcntl

import pytest

from pln2033 import bus as B  # noqa: N812
from pln2033.errors import SpiError


def test_struct_spi_ioc_transfer_matches_the_kernel_header():
    t = B.SpiIocTransfer
    assert ctypes.sizeof(t) == 32
    offsets = {name: getattr(t, name).offset for name, _ in t._fields_}
    assert offsets == {
        "tx_buf": 0,
        "rx_buf": 8,
        "len": 16,
        "speed_hz": 20,
        "delay_usecs": 24,
        "bits_per_word": 26,
        "cs_change": 27,
        "tx_nbits": 28,
        "rx_nbits": 29,
        "word_delay_usecs": 30,
        "pad": 31,
    }


def test_spi_ioc_message_request_numbers():
    # _IOW('k', 0, char[32 n]): the values C code gets from SPI_IOC_MESSAGE(n) on x86/ARM
    assert B.spi_ioc_message(1) == 0x40206B00
    assert B.spi_ioc_message(2) == 0x40406B00
    assert B.spi_ioc_message(511) == 0x7FE06B00
    assert B.MAX_SEGMENTS_PER_IOCTL == 511
    with pytest.raises(ValueError, match=r"1\.\.511"):
        B.spi_ioc_message(512)
    with pytest.raises(ValueError):
        B.spi_ioc_message(0)


class FakeKernel:
    """fcntl.ioctl on a spidev fd: records each message, MISO = MOSI + 1 (a loopback)."""

    def __init__(self, fail_errno=None):
        self.calls = []
        self.fail_errno = fail_errno

    def __call__(self, fd, request, arg):
        if self.fail_errno:
            raise OSError(self.fail_errno, "Remote I/O error")
        n = (request >> 16) & 0x3FFF
        assert n % 32 == 0 and request & 0xFFFF == 0x6B00 and request >> 30 == 1
        msg = []
        for t in arg[: n // 32]:
            tx = (ctypes.c_uint8 * t.len).from_address(t.tx_buf)
            rx = (ctypes.c_uint8 * t.len).from_address(t.rx_buf)
            for i in range(t.len):
                rx[i] = (tx[i] + 1) & 0xFF
            msg.append((list(tx), t.delay_usecs, t.cs_change))
        self.calls.append((fd, msg))
        return 0


def test_one_frame_is_one_ioctl_with_a_delay_per_segment(monkeypatch):
    k = FakeKernel()
    monkeypatch.setattr(fcntl, "ioctl", k)
    rx = B.spi_message(7, [([0x50], 35), ([0] * 12, 0)])
    assert rx == [[0x51], [1] * 12]
    assert k.calls == [(7, [([0x50], 35, 0), ([0] * 12, 0, 0)])]


def test_a_long_frame_is_chunked_with_chip_select_kept_low(monkeypatch):
    k = FakeKernel()
    monkeypatch.setattr(fcntl, "ioctl", k)
    segs = [([0xE2], 15)] + [([i & 0xFF], 15) for i in range(4094)]  # an SROM upload
    rx = B.spi_message(3, segs)
    assert [len(m) for _fd, m in k.calls] == [511] * 8 + [4095 - 8 * 511]
    assert [m[-1][2] for _fd, m in k.calls] == [1] * 8 + [0]  # cs_change on all but the last
    assert all(c == 0 for _fd, m in k.calls for _tx, _d, c in m[:-1])
    assert rx[1:] == [[(i + 1) & 0xFF] for i in range(4094)]
    # the bufsiz limit splits by bytes too
    k.calls.clear()
    B.spi_message(3, [([0] * 3000, 0), ([0] * 3000, 0)], bufsiz=4096)
    assert len(k.calls) == 2
    with pytest.raises(ValueError, match="bufsiz"):
        B.spi_message(3, [([0] * 5000, 0)], bufsiz=4096)


def test_bad_segments_and_kernel_errors(monkeypatch):
    monkeypatch.setattr(fcntl, "ioctl", FakeKernel(fail_errno=121))
    with pytest.raises(SpiError, match=r"/dev/spidev1\.0 failed: Remote I/O error"):
        B.spi_message(3, [([1], 0)], "/dev/spidev1.0")
    with pytest.raises(ValueError, match="delay 70000"):
        B.spi_message(3, [([1], 70000)])
    with pytest.raises(ValueError, match=r"0\.\.255"):
        B.spi_message(3, [([256], 0)])
    assert B.spi_message(3, []) == []


def test_spidev_bus_uses_its_file_descriptor(monkeypatch):
    k = FakeKernel()
    monkeypatch.setattr(fcntl, "ioctl", k)

    class Dev:
        def fileno(self):
            return 42

    bus = object.__new__(B.SpidevBus)
    bus.path, bus._dev = "/dev/spidev1.0", Dev()
    assert isinstance(bus, B.SegmentedSpiBus)
    assert bus.xfer_segments([([0x00], 160), ([0], 20)]) == [[1], [1]]
    assert k.calls[0][0] == 42
    with pytest.raises(ValueError, match="SPI mode 4"):
        B.SpidevBus("/dev/spidev1.0", mode=4)
