"""The cameras of this machine, their sensor modes, and what a stream of one would be.

Used by ``qrfield camera list|check`` and the app's Camera tab. Raspberry Pi cameras are listed
through picamera2 (each camera is opened briefly to read its sensor modes: not while another
program uses it); USB cameras through the V4L2 devices in /sys/class/video4linux (the Pi's own
ISP, codec and CSI-2 receiver nodes are left out) opened with OpenCV; on other systems OpenCV
indices 0..3. The picamera2 stand-ins are listed only when asked for, marked SIMULATED.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2

from qrfield.camera import CameraModel, resolve_camera
from qrfield.sources.base import SourceError
from qrfield.sources.opencv import fourcc_text, quietly_open
from qrfield.sources.picamera import SENSOR_PRESETS, Picamera2Source, import_picamera2
from qrfield.sources.sensor_modes import SensorMode

#: V4L2 device names of the Raspberry Pi's own video nodes (not cameras OpenCV can read).
PI_INTERNAL_NODES = ("unicam", "bcm2835-isp", "bcm2835-codec", "rp1-cfe", "pispbe", "rpi-hevc-dec", "bcm2835")
V4L2_SYSFS = Path("/sys/class/video4linux")


@dataclass
class FoundCamera:
    """One camera: the --source value that opens it, a title, and what is known about it."""

    source: str
    title: str
    lines: list[str] = field(default_factory=list)
    simulated: bool = False


def picamera2_cameras(picamera2_class: Any, source: str = "picamera2") -> list[FoundCamera]:
    """The cameras picamera2 (or a stand-in class) sees, each with its sensor modes."""
    found = []
    for info in picamera2_class.global_camera_info():
        num = int(info.get("Num", len(found)))
        title = f"camera {num}: {info.get('Model', '?')} ({info.get('Id', '')})"
        entry = FoundCamera(source if num == 0 else f"{source} --picamera-camera-num {num}", title)
        try:
            camera = picamera2_class(num)
        except Exception as exc:  # busy, or gone since the listing
            entry.lines.append(f"cannot open it ({exc}): in use by another program?")
            found.append(entry)
            continue
        try:
            resolution = tuple(camera.sensor_resolution)
            entry.lines.append(f"full resolution {resolution[0]}x{resolution[1]}")
            model = str(camera.camera_properties.get("Model", ""))
            preset = SENSOR_PRESETS.get(model)
            if preset:
                entry.lines.append(f"preset camera model: {preset}")
            if "AfMode" in camera.camera_controls:
                lo, hi, default = camera.camera_controls["LensPosition"]
                entry.lines.append(f"autofocus: LensPosition {lo:g}..{hi:g} dioptres (default {default:g})")
            modes = [SensorMode.from_picamera2(m) for m in camera.sensor_modes if "crop_limits" in m]
            entry.lines.append("sensor modes (size, fps, crop in full-resolution pixels):")
            entry.lines += [f"  {m.describe()}" for m in modes]
        finally:
            for method in ("stop", "close"):
                with contextlib.suppress(Exception):  # closing a listed camera must not end the list
                    getattr(camera, method)()
        found.append(entry)
    return found


def usb_cameras() -> tuple[list[FoundCamera], str]:
    """USB cameras OpenCV can open, and a line saying where it looked."""
    if V4L2_SYSFS.is_dir():
        nodes = []
        for path in sorted(V4L2_SYSFS.glob("video*"), key=lambda p: int(p.name[5:] or 0)):
            name = (path / "name").read_text(errors="replace").strip() if (path / "name").exists() else ""
            if not any(name.startswith(internal) for internal in PI_INTERNAL_NODES):
                nodes.append((int(path.name[5:]), name))
        where = (
            f"{len(nodes)} V4L2 device(s) in {V4L2_SYSFS}" if nodes else f"no V4L2 devices in {V4L2_SYSFS}"
        )
    elif sys.platform.startswith("linux"):
        nodes, where = [], f"no V4L2 devices: {V4L2_SYSFS} is absent"
    else:
        nodes = [(i, "") for i in range(4)]
        where = "OpenCV camera indices 0..3"
    found = []
    for index, name in nodes:
        cap = quietly_open(index)
        try:
            if not cap.isOpened():
                continue  # e.g. a UVC camera's metadata node
            w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
            fourcc = fourcc_text(cap.get(cv2.CAP_PROP_FOURCC))
        finally:
            cap.release()
        title = (
            f"usb:{index}"
            + (f": {name}" if name else "")
            + (f" (/dev/video{index})" if os.name == "posix" else "")
        )
        found.append(FoundCamera(f"usb:{index}", title, [f"default format {w}x{h} {fourcc}".rstrip()]))
    return found, where


def list_cameras(include_simulated: bool = False) -> tuple[list[FoundCamera], list[str]]:
    """Every camera found, and one line per kind of camera saying why none (or where it looked)."""
    found: list[FoundCamera] = []
    reasons: list[str] = []
    try:
        cameras = picamera2_cameras(import_picamera2())
        found += cameras
        if not cameras:
            reasons.append("picamera2: no Raspberry Pi camera attached")
    except SourceError as exc:
        reasons.append(f"picamera2: {exc}")
    except Exception as exc:  # libcamera's own errors (no camera manager, ...)
        reasons.append(f"picamera2: {type(exc).__name__}: {exc}")
    usb, where = usb_cameras()
    found += usb
    if not usb:
        reasons.append(f"USB: no camera OpenCV can open ({where})")
    if include_simulated:
        from qrfield.sources.picamera_sim import SENSORS, picamera2_class

        for sensor in SENSORS:
            for entry in picamera2_cameras(picamera2_class(sensor), f"picamera2-sim:{sensor}"):
                entry.title = f"SIMULATED {entry.title} [picamera2 stand-in]"
                entry.simulated = True
                found.append(entry)
    return found, reasons


def stream_report(source: Any, camera: CameraModel | None) -> list[str]:
    """What an opened source delivers and the camera model its frames are measured with (the
    app's Camera tab): a picamera2 stream's full report, else the source and ``camera``."""
    if isinstance(source, Picamera2Source):
        return [f"source: {source.description}", *source.stream.lines()]
    lines = [f"source: {source.description}"]
    if camera is not None:
        lines.append(f"camera model: {camera.name}: {camera.summary()}")
    return lines + [f"note: {n}" for n in source.notes]


def check_lines(source: Any, profile: CameraModel | None, frames: int = 3) -> list[str]:
    """What the opened ``source`` delivers and the camera model of its frames, one fact a line.

    A picamera2 source without a ``profile`` is given the preset of its sensor (said so). Reads
    ``frames`` frames to show the delivered size and the frame times.
    """
    lines = [f"source: {source.description}"]
    if isinstance(source, Picamera2Source):
        if profile is None:
            preset = SENSOR_PRESETS.get(source.stream.sensor)
            if preset:
                lines.append(
                    f"camera model: the {source.stream.sensor}'s preset {preset} (name yours with --camera)"
                )
                source.use_profile(resolve_camera(preset))
        times = [source.read().t_capture for _ in range(frames)]
        lines += source.stream.lines()
        steps = ", ".join(f"{1000 * (b - a):.1f}" for a, b in itertools.pairwise(times))
        frames_line = f"frames: {frames} read" + (f"; time steps {steps} ms" if steps else "")
    else:
        frame = None
        for _ in range(frames):
            frame = source.read()
        frames_line = f"frames: {frames} read at {frame.size[0]}x{frame.size[1]}" if frame else ""
        camera = getattr(source, "profile", None) or profile
        if camera is not None:
            lines.append(f"camera model: {camera.name}: {camera.summary()} (the frames have its size)")
    for note in source.notes:  # the model is in the report already, and some notes are too
        if not note.startswith("camera model: ") and f"note: {note}" not in lines:
            lines.append(f"note: {note}")
    return [*lines, frames_line] if frames_line else lines
