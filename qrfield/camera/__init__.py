"""Camera models: the model (pinhole intrinsics plus OpenCV's five distortion coefficients), its
fields' checks, the lens-model check, profiles by name and the commands' camera options.

Conventions (docs/conventions.md): pixels follow OpenCV, the centre of the top-left pixel is (0, 0).
Modules: ``model`` (:class:`CameraModel`), ``fields`` (the error, the field checks), ``distortion``
(can OpenCV invert the lens model), ``profiles`` (names, folders, presets), ``options`` (argparse).
Everything public is importable from ``qrfield.camera`` (the public API: ``qrfield.camera.CameraModel``).
"""

from qrfield.camera.distortion import check_distortion, distortion_note
from qrfield.camera.fields import (
    ASPECT_TOLERANCE,
    DEFAULT_CAMERA,
    REQUIRED_FIELDS,
    SENSOR_FIELDS,
    CameraModelError,
    check_crop,
    format_crop,
    image_distance_mm,
    sensor_fields,
)
from qrfield.camera.model import CameraModel
from qrfield.camera.options import add_camera_arguments, camera_from_args
from qrfield.camera.profiles import (
    camera_origin,
    parse_size,
    preset_dir,
    preset_names,
    resolve_camera,
    say_camera,
    user_profile_dirs,
)

__all__ = [
    "ASPECT_TOLERANCE",
    "DEFAULT_CAMERA",
    "REQUIRED_FIELDS",
    "SENSOR_FIELDS",
    "CameraModel",
    "CameraModelError",
    "add_camera_arguments",
    "camera_from_args",
    "camera_origin",
    "check_crop",
    "check_distortion",
    "distortion_note",
    "format_crop",
    "image_distance_mm",
    "parse_size",
    "preset_dir",
    "preset_names",
    "resolve_camera",
    "say_camera",
    "sensor_fields",
    "user_profile_dirs",
]
