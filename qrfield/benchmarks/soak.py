"""``qrfield benchmark soak``: would it survive a day at the bench? The real frame loop for a long stretch.

What runs is what ``qrfield run --headless --json-lines --serial PORT`` runs (the same settings,
the same :class:`~qrfield.engine.FrameLoop`, the same stdout sink and gripper link, built by
:mod:`qrfield.commands.run`'s own helpers), with the virtual bench as the source (wobbling, so the
tracker and the stream's history work), plus what an operator and a controller do over a session:

- the serial link streams to a pty pair (``--port pty``, default) or to ``loop://``; a controller
  thread at the other end reads every line, checks its CRC (:class:`~qrfield.serial.codec.FrameDecoder`),
  follows the $QRF seq for gaps, and sends ``$QRC,PING`` every ``--ping-s`` and ``$QRC,MEAS,5`` every
  ``--meas-s``, matching each answer to its command (one answer per command, in order). A pty
  ignores the baud: the link paces itself by ``--baud``;
- a session in a temporary folder logs a row (``--row-frames`` frames, the bench's own pose as the
  truth) every ``--row-s`` through :class:`~qrfield.sessions.recorder.RowRecorder`, the sink the app
  and ``session log`` use, and :meth:`qrfield.sessions.Session.log`;
- stdout's JSON lines go to /dev/null through the run's :class:`~qrfield.stdout_lines.LineWriter`.

Every ``--sample-frames`` frames a line is printed: elapsed time, frames, frame rate of the window,
RSS (/proc/self/status VmRSS, MB), Python threads alive and the process's OS threads, open file
descriptors (/proc/self/fd), the median and p99 of the capture-to-result latency and of the time
between frames over the window, $QRF lines received, seq gaps, lines that failed their CRC (or were
cut or malformed), commands sent / answered / answered wrongly, rows logged / rows in rows.csv.
At the end: the growth per hour after the warm-up (``--warmup-s``; least-squares slopes of RSS,
threads, fds and latency), the load average before and after, the CPU time; with
``--tracemalloc`` the allocation sites that grew most between the end of the warm-up and the end,
and (always) the Python object types whose count grew most (gc.get_objects).

Default: 3 minutes (it finishes); a bench day's figure: ``nice ./run.sh benchmark soak --minutes 30``
(docs/benchmarks.md, "soak").
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import os
import select
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

HELP = "run the headless frame loop with serial, commands and session logging for minutes; print growth"

#: The combination of the virtual bench's default pose (alpha 15, beta -20, gamma 10 degrees).
COMBO = "alpha+beta-gamma+"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, rate, seconds, seed, whole_number
    from qrfield.limits import MAX_BENCHMARK_COUNT

    parser.add_argument(
        "--minutes", type=seconds("--minutes"), default=3.0, help="how long to run, minutes (default 3)"
    )
    parser.add_argument(
        "--frames",
        type=count("--frames", 0, MAX_BENCHMARK_COUNT),
        default=0,
        help="stop after N frames instead (0 = --minutes decides; default 0)",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=1, help="the virtual bench's noise seed")
    parser.add_argument(
        "--sample-frames",
        type=whole_number("--sample-frames", 10, 1_000_000),
        default=300,
        help="frames between samples (default 300)",
    )
    parser.add_argument(
        "--warmup-s",
        type=seconds("--warmup-s"),
        default=60.0,
        help="samples before this are left out of the slopes, s (default 60)",
    )
    parser.add_argument(
        "--fps", type=rate("--fps"), default=0.0, help="the bench's frame rate (0 = as fast as it renders)"
    )
    parser.add_argument(
        "--x-mm",
        type=float,
        default=10.0,
        help="the bench's true x, mm (default 10; 150 wobbles the card across the image's right edge)",
    )
    parser.add_argument(
        "--wobble-mm", type=seconds("--wobble-mm"), default=10.0, help="the bench's x wobble, mm (10)"
    )
    parser.add_argument(
        "--port", choices=("pty", "loop"), default="pty", help="the serial twin (default pty)"
    )
    parser.add_argument(
        "--baud", type=whole_number("--baud", 1200, 4_000_000), default=115200, help="default 115200"
    )
    parser.add_argument("--ping-s", type=seconds("--ping-s"), default=1.0, help="PING every (default 1 s)")
    parser.add_argument("--meas-s", type=seconds("--meas-s"), default=5.0, help="MEAS,5 every (default 5 s)")
    parser.add_argument("--row-s", type=seconds("--row-s"), default=10.0, help="a row every (default 10 s)")
    parser.add_argument(
        "--row-frames", type=whole_number("--row-frames", 1, 1000), default=10, help="frames per row (10)"
    )
    parser.add_argument(
        "--method", choices=("numerical", "ippe", "both"), default="both", help="pose methods (default both)"
    )
    parser.add_argument(
        "--tracemalloc",
        action="store_true",
        help="trace allocations (slower) and print the sites that grew most after the warm-up",
    )


# ------------------------------------------------------------------------------------ the process
def _status_kb(key: str) -> int:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return -1


def rss_mb() -> float:
    """Resident memory now (VmRSS), MB."""
    return _status_kb("VmRSS") / 1024.0


def os_threads() -> int:
    """The process's threads as the kernel counts them (OpenCV's and numpy's pools included)."""
    return _status_kb("Threads")


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def cpu_s() -> float:
    t = os.times()
    return t.user + t.system


def type_counts() -> collections.Counter[str]:
    import gc

    gc.collect()
    return collections.Counter(type(o).__qualname__ for o in gc.get_objects())


# ------------------------------------------------------------------------------------ the controller
@dataclass
class ControllerCounts:
    lines: int = 0  # good $QRF lines
    statuses: collections.Counter[str] = field(default_factory=collections.Counter)
    seq_gaps: int = 0  # lines missing between consecutive seqs
    bad: int = 0  # failed CRC, cut or malformed
    sent: int = 0  # commands sent
    answered: int = 0  # answers matched to their command
    wrong: int = 0  # answers to another command than the oldest waiting one
    meas_status: collections.Counter[str] = field(default_factory=collections.Counter)
    ping_ms: collections.deque[float] = field(default_factory=lambda: collections.deque(maxlen=1000))


class Controller:
    """The gripper controller at the far end: reads and checks every line, sends PING and MEAS,5."""

    def __init__(self, read: Any, write: Any, ping_s: float, meas_s: float) -> None:
        from qrfield.serial import codec

        self._read, self._write = read, write
        self.ping_s, self.meas_s = ping_s, meas_s
        self.decoder = codec.FrameDecoder()
        self.counts = ControllerCounts()
        self.waiting: collections.deque[tuple[str, float]] = collections.deque()  # (command, sent at)
        self._last_seq: int | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="soak controller", daemon=True)

    def start(self) -> Controller:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def snapshot(self) -> tuple[ControllerCounts, int]:
        import copy

        with self._lock:
            return copy.deepcopy(self.counts), len(self.waiting)

    def _send(self, command: str, *args: str) -> None:
        from qrfield.serial import codec

        with self._lock:
            self.waiting.append((command, time.monotonic()))
            self.counts.sent += 1
        self._write(codec.encode_command(command, *args))

    def _run(self) -> None:
        from qrfield.serial import codec

        next_ping = time.monotonic() + self.ping_s
        next_meas = time.monotonic() + self.meas_s
        while not self._stop.is_set():
            now = time.monotonic()
            if self.ping_s > 0 and now >= next_ping:
                next_ping += self.ping_s
                self._send("PING")
            if self.meas_s > 0 and now >= next_meas:
                next_meas += self.meas_s
                self._send("MEAS", "5")
            data = self._read()
            if not data:
                continue
            now = time.monotonic()
            items = self.decoder.feed(data)
            with self._lock:
                c = self.counts
                k = self.decoder.counters
                c.bad = k.bad_checksum + k.truncated + k.malformed + k.overlong
                for item in items:
                    if isinstance(item, codec.QrfFrame):
                        c.lines += 1
                        c.statuses[item.status] += 1
                        if self._last_seq is not None:
                            c.seq_gaps += (item.seq - self._last_seq - 1) % codec.SEQ_MODULUS
                        self._last_seq = item.seq
                    elif isinstance(item, codec.QraAnswer | codec.QrmMeasurement):
                        name = "MEAS" if isinstance(item, codec.QrmMeasurement) else item.command
                        if not self.waiting:
                            c.wrong += 1
                            continue
                        command, sent_at = self.waiting.popleft()
                        if command != name:
                            c.wrong += 1
                            continue
                        c.answered += 1
                        if name == "PING":
                            c.ping_ms.append((now - sent_at) * 1000.0)
                        else:
                            c.meas_status[item.status] += 1


def _pty_port() -> tuple[str, Any, Any, Any]:
    """A pty pair: the device the link opens, and the controller's read and write at the master end."""
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)  # no echo, no CR LF translation: bytes as a UART carries them

    def read() -> bytes:
        ready, _, _ = select.select([master], [], [], 0.02)
        if not ready:
            return b""
        try:
            return os.read(master, 65536)
        except OSError:
            return b""

    def write(data: bytes) -> None:
        os.write(master, data)

    def close() -> None:
        for fd in (master, slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    return os.ttyname(slave), read, write, close


# ------------------------------------------------------------------------------------ the operator
class Operator:
    """Logs a row every ``row_s`` (the bench's pose as truth) into ``session``, as the app does."""

    def __init__(self, session: Any, recorder: Any, row_s: float, row_frames: int) -> None:
        self.session, self.recorder = session, recorder
        self.row_s, self.row_frames = row_s, row_frames
        self.logged = 0
        self.failed: collections.Counter[str] = collections.Counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="soak operator", daemon=True)

    def start(self) -> Operator:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10.0)

    def _run(self) -> None:
        while not self._stop.wait(self.row_s):
            measurement = self.recorder.measure(
                None,
                self.row_frames,
                follow_bench=True,
                combo=COMBO,
                until=self._stop.is_set,
                frame_timeout_s=10.0,
            )
            if measurement is None:
                self.failed[self.recorder.last_problem[:40]] += 1
                continue
            outcome = self.session.log(measurement)
            if outcome.ok:
                self.logged += 1
            else:
                self.failed[str(outcome.reason)[:40]] += 1

    def rows_on_disk(self) -> int:
        with open(self.session.rows_path, "rb") as rows:
            return max(0, sum(1 for _ in rows) - 1)


# ------------------------------------------------------------------------------------ the sampler
@dataclass
class Sample:
    t_s: float
    frames: int
    fps: float
    cpu_ms: float
    rss_mb: float
    threads: int
    os_threads: int
    fds: int
    latency_med: float
    latency_p99: float
    period_med: float
    period_p99: float
    lines: int
    seq_gaps: int
    bad: int
    sent: int
    answered: int
    wrong: int
    rows: int
    rows_csv: int
    said: int


class Sampler:
    """A frame loop sink: per-frame latency and period; a :class:`Sample` every ``every`` frames."""

    def __init__(
        self, every: int, deadline: float, controller: Controller, operator: Operator, said: Any
    ) -> None:
        import numpy as np

        self.np = np
        self.every, self.deadline = every, deadline
        self.controller, self.operator, self.said = controller, operator, said
        self.loop: Any = None
        self.samples: list[Sample] = []
        self.t0 = time.monotonic()
        self._last_at = self.t0
        self._window_at, self._window_frames, self._window_cpu = self.t0, 0, cpu_s()
        self.latency = np.zeros(every)
        self.period = np.zeros(every)
        self.frames = 0
        self.statuses: collections.Counter[str] = collections.Counter()

    # the Sink protocol
    def on_result(self, result: Any, simulated: bool) -> None:
        now = time.monotonic()
        i = self.frames % self.every
        self.latency[i] = float(getattr(result, "latency_ms", float("nan")))
        self.period[i] = (now - self._last_at) * 1000.0
        self._last_at = now
        self.frames += 1
        self.statuses[str(getattr(result, "status", ""))] += 1
        if self.frames % self.every == 0:
            self.sample(now)
        if now >= self.deadline and self.loop is not None:
            self.loop.stop()

    def on_source_down(self, reason: str) -> None:
        pass

    def on_source_up(self) -> None:
        pass

    def sample(self, now: float) -> None:
        np = self.np
        counts, _waiting = self.controller.snapshot()
        fps = (self.frames - self._window_frames) / max(1e-9, now - self._window_at)
        cpu = cpu_s()
        cpu_ms = 1000.0 * (cpu - self._window_cpu) / max(1, self.frames - self._window_frames)
        self._window_at, self._window_frames, self._window_cpu = now, self.frames, cpu
        s = Sample(
            t_s=now - self.t0,
            frames=self.frames,
            fps=fps,
            cpu_ms=cpu_ms,
            rss_mb=rss_mb(),
            threads=threading.active_count(),
            os_threads=os_threads(),
            fds=open_fds(),
            latency_med=float(np.nanmedian(self.latency)),
            latency_p99=float(np.nanpercentile(self.latency, 99)),
            period_med=float(np.median(self.period)),
            period_p99=float(np.percentile(self.period, 99)),
            lines=counts.lines,
            seq_gaps=counts.seq_gaps,
            bad=counts.bad,
            sent=counts.sent,
            answered=counts.answered,
            wrong=counts.wrong,
            rows=self.operator.logged,
            rows_csv=self.operator.rows_on_disk(),
            said=sum(self.said.values()),
        )
        self.samples.append(s)
        print(_sample_line(s), flush=True)


HEADER = (
    f"{'t s':>7}{'frames':>8}{'fps':>6}{'CPU/f':>6}{'RSS MB':>8}{'thr':>5}{'OS thr':>7}{'fds':>5}"
    f"{'lat med':>8}{'lat p99':>8}{'per med':>8}{'per p99':>8}{'$QRF':>8}{'gaps':>5}{'bad':>4}"
    f"{'cmds':>6}{'answ':>6}{'wrong':>6}{'rows':>5}{'csv':>5}{'said':>6}"
)


def _sample_line(s: Sample) -> str:
    return (
        f"{s.t_s:>7.0f}{s.frames:>8}{s.fps:>6.1f}{s.cpu_ms:>6.1f}{s.rss_mb:>8.1f}{s.threads:>5}{s.os_threads:>7}{s.fds:>5}"
        f"{s.latency_med:>8.1f}{s.latency_p99:>8.1f}{s.period_med:>8.1f}{s.period_p99:>8.1f}"
        f"{s.lines:>8}{s.seq_gaps:>5}{s.bad:>4}{s.sent:>6}{s.answered:>6}{s.wrong:>6}{s.rows:>5}{s.rows_csv:>5}{s.said:>6}"
    )


def _slope_per_hour(samples: list[Sample], name: str) -> tuple[float, float]:
    """Least-squares slope of ``name`` against time, per hour, and the RMS of the residuals."""
    import numpy as np

    t = np.array([s.t_s for s in samples]) / 3600.0
    y = np.array([getattr(s, name) for s in samples], dtype=float)
    if len(t) < 3 or np.ptp(t) <= 0:
        return float("nan"), float("nan")
    slope, intercept = np.polyfit(t, y, 1)
    return float(slope), float(np.sqrt(np.mean((y - (slope * t + intercept)) ** 2)))


# ------------------------------------------------------------------------------------ the run
def _run_args(args: argparse.Namespace, config_dir: Path, port: str) -> argparse.Namespace:
    from qrfield.commands import run as run_command

    parser = argparse.ArgumentParser(prog="qrfield run")
    run_command.add_arguments(parser)
    return parser.parse_args(
        [
            "--headless",
            "--json-lines",
            "--config-dir",
            str(config_dir),
            "--source",
            "virtual",
            "--camera",
            "picam-v2@640x480",
            "--side-mm",
            "50",
            "--method",
            args.method,
            "--virtual-fps",
            f"{args.fps:g}",
            "--virtual-seed",
            str(args.seed),
            "--virtual-wobble-deg",
            "5",
            "--virtual-wobble-mm",
            f"{args.wobble_mm:g}",
            f"--virtual-x-mm={args.x_mm:g}",
            "--virtual-wobble-period-s",
            "8",
            "--serial",
            port,
            "--serial-baud",
            str(args.baud),
        ]
    )


def run(args: argparse.Namespace) -> int:
    import tempfile
    import tracemalloc

    from qrfield.commands import run as run_command
    from qrfield.engine import FrameLoop
    from qrfield.handeye import PoseFrame
    from qrfield.runconfig import effective_settings
    from qrfield.sessions import Session
    from qrfield.sessions.recorder import RowRecorder
    from qrfield.stdout_lines import LineWriter

    load_before = os.getloadavg()
    cpu0 = cpu_s()
    notes: collections.Counter[str] = collections.Counter()

    def say(message: str) -> None:
        key = message[:25]  # coarse: the counter of the benchmark itself stays small
        notes[key] += 1
        if notes[key] <= 2:
            print(f"  note: {message}", file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory(prefix="qrfield-soak-") as tmp:
        folder = Path(tmp)
        if args.port == "pty":
            device, read, write, close_port = _pty_port()
        else:
            device, read, write, close_port = "loop://", None, None, None
        run_args = _run_args(args, folder / "config", device)
        effective = effective_settings(run_args, strict=True)
        config = effective.run_config()
        pose_frame = PoseFrame.from_settings(effective.groups["handeye"], run_args.config_dir)
        handeye = run_command._handeye_commands(effective, run_args, config, say)
        link = run_command._gripper_link(effective.serial_settings(), say, config, pose_frame, handeye)
        if args.port == "loop":
            # loop:// hands the link its own lines back; the controller would need the port: the
            # link's own decoder counts them, commands are not sent.
            def read() -> bytes:
                time.sleep(0.02)
                return b""

            def write(data: bytes) -> None:
                pass

        devnull = open(os.devnull, "w")  # noqa: SIM115 (closed below, after the writer)
        writer = LineWriter(devnull)
        events = run_command._Events(say, writer, link)
        stdout_sink = run_command._StdoutSink(writer, True)
        session = Session.create(
            folder / "sessions",
            "soak",
            camera=config.camera,
            side_mm=config.side_mm,
            solver=config.methods[0],
        )
        recorder = RowRecorder(session.info)
        controller = Controller(read, write, args.ping_s, args.meas_s)
        operator = Operator(session, recorder, args.row_s, args.row_frames)
        deadline = time.monotonic() + (args.minutes * 60.0 if not args.frames else 1e12)
        sampler = Sampler(args.sample_frames, deadline, controller, operator, notes)
        loop = FrameLoop(
            config, events=events, sinks=[stdout_sink, link, recorder, sampler], max_frames=args.frames
        )
        events.loop = sampler.loop = loop
        print(
            f"qrfield benchmark soak: {f'{args.frames} frames' if args.frames else f'{args.minutes:g} min'}"
            f" of `qrfield run --headless --json-lines --serial` on the virtual bench ({config.camera.name}, "
            f"{args.fps:g} fps (0 = as fast as it renders), method {args.method}, seed {args.seed}); serial "
            f"{args.port} at {args.baud} baud; PING every {args.ping_s:g} s, MEAS,5 every {args.meas_s:g} s; "
            f"a row of {args.row_frames} frames every {args.row_s:g} s; load before "
            + ", ".join(f"{v:.2f}" for v in load_before),
            flush=True,
        )
        print(
            "CPU/f: the process's CPU ms a frame (loop, link, controller, operator); "
            "lat: capture to result ms; per: ms between frames; $QRF: lines the controller read; gaps: "
            "seq gaps; bad: CRC/cut/malformed; cmds/answ/wrong: commands sent, answered, answered out "
            "of order; rows: logged; csv: rows in rows.csv; said: messages the run said on stderr (notes)",
            flush=True,
        )
        print(HEADER, flush=True)
        controller.start()
        operator.start()
        warm: dict[str, Any] = {}

        def after_warmup() -> None:
            warm["types"] = type_counts()
            if args.tracemalloc:
                warm["snapshot"] = tracemalloc.take_snapshot()

        if args.tracemalloc:
            tracemalloc.start(10)
        warm_timer = threading.Timer(args.warmup_s, after_warmup)
        warm_timer.daemon = True
        warm_timer.start()
        try:
            ending = loop.run()
        finally:
            warm_timer.cancel()
            operator.stop()
            end_snapshot = tracemalloc.take_snapshot() if args.tracemalloc and "snapshot" in warm else None
            end_types = type_counts() if "types" in warm else None
            link.close()
            time.sleep(0.2)  # the last lines reach the controller
            controller.stop()
            writer.close(1.0)
            devnull.close()
            rows_csv = operator.rows_on_disk()
            session.close()
            if close_port is not None:
                close_port()
        status = link.status()
        counts, waiting = controller.snapshot()
    cpu = cpu_s() - cpu0
    elapsed = time.monotonic() - sampler.t0
    load_after = os.getloadavg()
    samples = sampler.samples
    print(
        f"ended: {ending} after {sampler.frames} frames in {elapsed:.0f} s "
        f"({sampler.frames / elapsed:.1f} fps); CPU {cpu:.0f} s ({cpu / elapsed:.2f} of a core, "
        f"{1000 * cpu / max(1, sampler.frames):.1f} ms a frame); "
        "load after " + ", ".join(f"{v:.2f}" for v in load_after)
    )
    print(f"frame statuses: {dict(sampler.statuses)}")
    print(
        f"serial: link wrote {status.frames_sent} $QRF lines ({status.frames_dropped} superseded), "
        f"{status.answers_sent} answers, {status.errors} errors, {status.reconnects} reconnects; the "
        f"controller read {counts.lines} $QRF lines {dict(counts.statuses)}, {counts.seq_gaps} seq gaps, "
        f"{counts.bad} bad lines; commands {counts.sent} sent, {counts.answered} answered, {counts.wrong} "
        f"wrong, {waiting} unanswered at the end; MEAS answers {dict(counts.meas_status)}"
    )
    if counts.ping_ms:
        import numpy as np

        ping = np.array(counts.ping_ms)
        print(f"PING answered in median {np.median(ping):.1f} ms, max {ping.max():.1f} ms (last {ping.size})")
    print(
        f"session: {operator.logged} rows logged, {rows_csv} in rows.csv; "
        f"not logged: {dict(operator.failed) or 0}"
    )
    after = [s for s in samples if s.t_s >= args.warmup_s]
    if len(after) >= 3:
        print(
            f"growth per hour after the {args.warmup_s:g} s warm-up ({len(after)} samples; "
            "+- = RMS residual):"
        )
        for name, unit in (
            ("rss_mb", "MB"),
            ("threads", "threads"),
            ("os_threads", "OS threads"),
            ("fds", "fds"),
            ("cpu_ms", "CPU ms a frame"),
            ("latency_med", "ms latency (median)"),
            ("period_med", "ms between frames (median)"),
            ("said", "messages said"),
        ):
            slope, rms = _slope_per_hour(after, name)
            first, last = getattr(after[0], name), getattr(after[-1], name)
            print(f"  {unit:<28}{slope:>+10.2f} /h  (+- {rms:.2f}; {first:g} -> {last:g})")
    else:
        print(f"growth per hour: too few samples after the {args.warmup_s:g} s warm-up (run longer)")
    if end_types is not None:
        grown = [(n, end_types[n] - warm["types"].get(n, 0)) for n in end_types]
        grown = sorted((g for g in grown if g[1] > 0), key=lambda g: -g[1])[:12]
        print(
            "object types that grew after the warm-up (gc.get_objects): "
            + (", ".join(f"{n} +{d}" for n, d in grown) or "none")
        )
    if end_snapshot is not None:
        print("allocation sites that grew most after the warm-up (tracemalloc):")
        for stat in end_snapshot.compare_to(warm["snapshot"], "lineno")[:12]:
            print(f"  {stat}")
    return 0
