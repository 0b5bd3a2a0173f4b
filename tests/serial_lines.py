"""Real lines from a run: what a GripperLink writes to its port, collected at the far end of a relay.

:func:`record_lines` drives a :class:`qrfield.serial.controller.GripperLink` as a frame loop does
(seeded varied poses, every status, unknown sigmas, angles at their limits, the source going down
and up, pauses long enough for STALE) and plays the controller (PING, HELLO, RATE, STREAM, MEAS,
unknown commands, a wrong CRC), over a pty behind a :class:`qrfield.serial.relay.UartRelay`; the
lines are the bytes that arrived, as a controller's UART would have received them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from serial_truth import command_line

from qrfield.serial.controller import GripperLink
from qrfield.serial.link import CONNECTED, SerialLinkSettings
from qrfield.serial.relay import UartRelay


@dataclass
class _Pose:
    position_mm: np.ndarray
    angles_deg: np.ndarray
    position_std_mm: np.ndarray
    angles_std_deg: np.ndarray
    converged: bool = True


@dataclass
class _Result:
    t_ms: int
    status: str
    primary: _Pose | None
    t_capture: float
    ambiguous: bool = False
    extra: dict = field(default_factory=dict)


def _pose(rng: np.random.Generator) -> _Pose:
    position = rng.uniform([-500, -500, 50], [500, 500, 3000]) * rng.choice([1, 1, 1, 100])
    angles = np.array([rng.uniform(-180, 180), rng.uniform(-90, 90), rng.uniform(-180, 180)])
    k = rng.integers(0, 10)
    if k == 0:
        angles = np.array([180.0, 90.0, -179.99])
    elif k == 1:
        angles = np.array([-179.999, -90.0, 0.004])
    sigma = rng.exponential([0.3, 0.3, 2.0, 0.2, 0.2, 0.1]) * rng.choice([1, 1, 1e4])
    sigma[rng.random(6) < 0.1] = np.nan  # unknown: written empty
    return _Pose(np.clip(position, -999999, 999999), angles, sigma[:3], sigma[3:])


COMMANDS = [
    ("PING",),
    ("HELLO",),
    ("RATE", "0"),
    ("STREAM", "ON"),
    ("MEAS", "2"),
    ("MEAS", "1"),
    ("HOME",),
    ("PING", "1"),
    ("TOOL",),
    ("MEAS", "0"),
]


def record_lines(n_lines: int, seed: int = 22, timeout_s: float = 120.0) -> list[bytes]:
    """At least ``n_lines`` complete lines (CR LF included) as they arrived; seeded."""
    rng = np.random.default_rng(seed)
    relay = UartRelay(400_000)
    settings = SerialLinkSettings(port=relay.device, baud=4_000_000, max_rate_hz=0, stale_after_s=0.02)
    link = GripperLink(settings)
    link.set_context(side_mm=50.0, camera="virtual-bench")
    link.start()
    try:
        assert link.wait_for_state(CONNECTED, 5), link.status()
        t0 = time.monotonic()
        k = 0
        while len(relay.lines) < n_lines:
            assert time.monotonic() - t0 < timeout_s, f"only {len(relay.lines)} lines"
            k += 1
            now = time.monotonic()
            t_ms = round((now - t0) * 1000)
            kind = rng.integers(0, 20)
            if kind < 12:
                result = _Result(t_ms, "OK", _pose(rng), now, ambiguous=bool(rng.random() < 0.2))
                link.on_result(result, simulated=bool(rng.random() < 0.3))
            elif kind < 15:
                link.on_result(_Result(t_ms, str(rng.choice(["NOQR", "NOCONV", "ERROR"])), None, now), False)
            elif kind == 15:
                relay.send(command_line(*COMMANDS[rng.integers(0, len(COMMANDS))]))
            elif kind == 16 and rng.random() < 0.05:
                relay.send(b"$QRC,PING*0000\r\n")
            elif kind == 17 and rng.random() < 0.05:
                link.on_source_down("test")
                time.sleep(0.03)
                link.on_source_up()
            elif kind == 18 and rng.random() < 0.05:
                time.sleep(0.05)  # STALE
            time.sleep(0.0001)
    finally:
        link.close()
        time.sleep(0.05)
        relay.close()
    return [line for _, line in relay.lines]
