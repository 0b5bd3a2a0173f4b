"""Opening the serial port: accepted names, exclusivity, who holds a busy port, the ports to offer.

docs/conventions.md: the port is opened exclusively, and a second qrfield on the same port refuses
with a clear error. A device path is opened with pyserial's ``exclusive=True``, which takes an
``flock`` on the open device (pyserial's serialposix.py: ``fcntl.flock(fd, LOCK_EX | LOCK_NB)``):
a second qrfield, or any program that locks the same way, cannot open it, and :class:`PortBusyError`
names the port and, on Linux, the process that has it open (read from ``/proc/<pid>/fd``).

Accepted names: a device path (``/dev/ttyUSB0``, ``COM3``, a pty) or ``loop://`` (pyserial's
loopback, the simulated port). Other pyserial URLs (``socket://``, ``rfc2217://``, ...) send the
gripper's poses over a network and are refused unless ``allow_url`` is set
(``--serial-allow-url``): :func:`check_port_name`.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

LOOP_URL = "loop://"


class PortBusyError(OSError):
    """The port is held by another program (or another link of this one); the message names both."""


class PortLike(Protocol):
    """The part of a pyserial Serial object the link uses (fakes in tests implement just this)."""

    def write(self, data: bytes) -> int | None: ...
    def read(self, size: int = 1) -> bytes: ...
    def close(self) -> None: ...


def is_url(port: str) -> bool:
    """True for a pyserial URL (``scheme://...``), loop:// included."""
    return "://" in port


def check_port_name(port: str, allow_url: bool = False) -> str:
    """``port`` if it may be opened; ValueError saying why not (empty, or a URL other than loop://
    without ``allow_url``)."""
    if not isinstance(port, str) or not port.strip():
        raise ValueError("no serial port given: give a device path (/dev/ttyUSB0, COM3) or loop://")
    if is_url(port) and port != LOOP_URL and not allow_url:
        raise ValueError(
            f"serial port {port!r} is a URL: only device paths and {LOOP_URL} are accepted "
            "(give --serial-allow-url, or allow_url in app.json's serial section, to send poses there)"
        )
    return port


def port_holders(device: str) -> list[tuple[int, str]]:
    """(pid, command line) of the processes that have ``device`` open, as far as ``/proc`` shows
    (Linux; other processes' fds are visible to the same user or root); [] where unknown."""
    try:
        target = os.path.realpath(device)
        procs = list(Path("/proc").iterdir())
    except OSError:
        return []
    found = []
    for proc in procs:
        if not proc.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            for fd in (proc / "fd").iterdir():
                with contextlib.suppress(OSError):
                    if os.readlink(fd) == target:
                        raw = (proc / "cmdline").read_bytes()
                        command = " ".join(part.decode(errors="replace") for part in raw.split(b"\0") if part)
                        found.append((int(proc.name), command))
                        break
    return found


def lock_holders(device: str) -> list[int]:
    """The pids holding an flock on ``device``, from ``/proc/locks`` (Linux); [] where unknown."""
    try:
        st = os.stat(device)
        text = Path("/proc/locks").read_text()
    except OSError:
        return []
    want = (os.major(st.st_dev), os.minor(st.st_dev), st.st_ino)
    pids = []
    for line in text.splitlines():
        parts = line.split()
        # "1: FLOCK  ADVISORY  WRITE 11784 00:05:3 0 EOF" (a waiting lock has "->" after the number)
        parts = [p for p in parts if p != "->"]
        if len(parts) < 6 or parts[1] != "FLOCK":
            continue
        with contextlib.suppress(ValueError):
            major, minor, inode = parts[5].split(":")
            if (int(major, 16), int(minor, 16), int(inode)) == want:
                pids.append(int(parts[4]))
    return pids


def busy_message(device: str) -> str:
    """One line: the port is in use, and by whom when known (the lock's holder, else who has it open)."""
    locked = set(lock_holders(device))
    holders = port_holders(device)
    if locked:
        holders = [h for h in holders if h[0] in locked] or [(pid, "") for pid in sorted(locked)]
    if not holders:
        return f"serial port {device} is in use by another program (it holds the port's lock)"
    own = os.getpid()
    who = "; ".join(
        f"pid {pid}" + (" (this process)" if pid == own else "") + (f": {cmd[:80]}" if cmd else "")
        for pid, cmd in holders[:3]
    )
    return f"serial port {device} is in use by {who}"


def open_pyserial(settings: Any) -> PortLike:
    """Open ``settings.port`` (a :class:`~qrfield.serial.link.SerialLinkSettings`) with pyserial,
    8N1, non-blocking reads; a device path exclusively. PortBusyError when another program holds
    it, ValueError for a name not accepted (:func:`check_port_name`), pyserial's error otherwise."""
    import serial

    port = check_port_name(settings.port, getattr(settings, "allow_url", False))
    kwargs: dict[str, Any] = dict(
        baudrate=settings.baud,
        bytesize=8,
        parity="N",
        stopbits=1,
        timeout=0,
        write_timeout=settings.write_timeout_s,
    )
    if not is_url(port) and os.name == "posix":
        kwargs["exclusive"] = True  # flock on the device (Windows opens a COM port exclusively anyway)
    try:
        return serial.serial_for_url(port, **kwargs)
    except serial.SerialException as exc:
        if "exclusively lock" in str(exc):
            raise PortBusyError(busy_message(port)) from None
        raise


@dataclass(frozen=True)
class PortInfo:
    """A port to offer in a chooser: its device (or URL) and a description."""

    device: str
    description: str


def list_ports() -> list[PortInfo]:
    """The machine's serial ports (pyserial's list_ports) followed by the simulated ``loop://``."""
    ports: list[PortInfo] = []
    try:
        from serial.tools import list_ports as pyserial_list_ports

        for info in sorted(pyserial_list_ports.comports(), key=lambda p: p.device):
            ports.append(PortInfo(info.device, info.description or info.device))
    except Exception as exc:  # a broken sysfs must not break the chooser
        ports.append(PortInfo("", f"(could not list ports: {exc})"))
    ports.append(PortInfo(LOOP_URL, "simulated port: pyserial loopback, every byte written is read back"))
    return ports
