"""Camera profiles by name: the folders searched, the shipped presets, ``NAME[@WxH]`` and ``PATH[@WxH]``,
and the line every command prints about the model it uses.

Search order (docs/cameras.md): ``$QRFIELD_CALIB_DIR``, the user's profile folder
(``~/.config/qrfield/calib``, where calibrations are saved), then the presets shipped in ``calib/``.
A ``./calib`` folder in the current folder is not searched by name: give its path.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from qrfield import paths
from qrfield.camera.fields import CameraModelError
from qrfield.camera.model import CameraModel
from qrfield.limits import IMAGE_SIDE_PX, LimitError


def preset_dir() -> Path:
    """Folder of the presets shipped with qrfield (the repository's ``calib/``)."""
    try:
        return Path(str(resources.files("qrfield_calib")))
    except ModuleNotFoundError:  # running from a source tree that is not installed
        return Path(__file__).resolve().parents[2] / "calib"


def user_profile_dirs() -> list[Path]:
    """Folders searched for ``NAME.json`` before the shipped presets, in order.

    ``$QRFIELD_CALIB_DIR`` (if set), then the user's profile folder. The current folder's
    ``./calib`` is not searched by name: see the module docstring.
    """
    dirs = []
    env = os.environ.get("QRFIELD_CALIB_DIR", "").strip()
    if env:
        dirs.append(Path(env).expanduser())
    dirs.append(paths.user_calib_dir())
    return dirs


def camera_origin(camera: CameraModel) -> str:
    """Where a camera model came from, with the file's path, for the line every command prints."""
    if not camera.path:
        return camera.notes.split(";")[0] if camera.notes else "built in"
    file = Path(camera.path)
    try:
        preset = file.resolve().parent == preset_dir().resolve()
    except OSError:
        preset = False
    if preset:
        return f"shipped preset {file}"
    shadowed = (preset_dir() / file.name).is_file() and any(file.parent == d for d in user_profile_dirs())
    note = " (it replaces the shipped preset of that name)" if shadowed else ""
    return f"profile {file}{note}"


def say_camera(camera: CameraModel, command: str) -> None:
    """One line on stderr naming the camera model and the file it came from (docs/cli.md)."""
    import sys

    print(f"qrfield {command}: camera {camera.name} from {camera_origin(camera)}", file=sys.stderr)


def preset_names() -> list[str]:
    """Names of the shipped presets (e.g. ``picam-v2``)."""
    return sorted(p.stem for p in preset_dir().glob("*.json"))


def parse_size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` (e.g. ``640x480``) into (width, height); CameraModelError if malformed."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise CameraModelError(f"image size {text!r} is not of the form WxH, e.g. 640x480")
    width, height = int(parts[0]), int(parts[1])
    if width <= 0 or height <= 0:
        raise CameraModelError(f"image size {text!r} must be positive")
    try:
        for value in (width, height):
            IMAGE_SIDE_PX.check(value, f"image size {text!r}")
    except LimitError as exc:
        raise CameraModelError(str(exc)) from None
    return width, height


def resolve_camera(spec: str) -> CameraModel:
    """A camera from ``NAME[@WxH]`` or ``PATH[@WxH]`` (see the module docstring)."""
    spec = spec.strip()
    if not spec:
        raise CameraModelError("empty camera name; give a preset such as picam-v2@640x480")
    # A file that exists is taken whole, so that a path may contain '@' (/home/me@lab/cam.json).
    whole_file = Path(spec).expanduser().is_file()
    base, _, size_text = spec.rpartition("@") if "@" in spec and not whole_file else (spec, "", "")
    size = parse_size(size_text) if size_text else None
    path = Path(base).expanduser()
    if base.endswith(".json") or os.sep in base or path.is_file():
        camera = CameraModel.load(path)
    else:
        if base in (".", "..") or "/" in base:  # a name, never a path outside the folders searched
            raise CameraModelError(f"no camera profile named {base!r}")
        candidates = [d / f"{base}.json" for d in user_profile_dirs()] + [preset_dir() / f"{base}.json"]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            local = Path("calib") / f"{base}.json"
            hint = (
                f"; ./{local} is not searched by name: give its path, --camera {local}"
                if local.is_file()
                else ""
            )
            raise CameraModelError(
                f"no camera profile named {base!r}; presets: {', '.join(preset_names())} "
                f"(or give a path to a JSON file, or --focal-px F --size WxH){hint}"
            )
        camera = CameraModel.load(found)
    return camera.scaled(*size) if size else camera
