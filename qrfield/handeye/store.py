"""``handeye.json``: a hand-eye calibration on disk (docs/conventions.md, "Hand-eye"; docs/handeye.md).

The fields of the conventions::

    {"setup": "eye-in-hand" | "eye-to-hand",
     "camera_to_tool" (eye-in-hand) | "camera_to_base" (eye-to-hand): 4x4 row-major, mm,
     "residual_mm", "residual_deg": RMS over the pairs, "n_pairs", "method"}

and ours beside them (a reader that knows only those keeps working): "format"
("qrfield-handeye/1"), "covariance" (6x6 of the transform's (dt mm, dtheta deg), in the tool/base
frame: R' = exp(dtheta) R, t' = t + dt), "translation_std_mm", "rotation_std_deg", "chi2", "dof",
"code_in_base" (eye-in-hand) or "code_in_tool" (eye-to-hand): the code's place found with it,
"pairs" (per pair: label, residual_mm, residual_deg), "created", "qrfield_version", and what the
caller adds (camera model name, QR side). A file written by hand needs only the conventions' fields;
its rotation may be rounded (it is made orthonormal again; more than 1e-3 off is refused).
Written all or nothing (:func:`qrfield.files.atomic_write_json`).
"""

from __future__ import annotations

import datetime as dt
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import qrfield
from qrfield.files import Fields, FileFormatError, atomic_write_json, describe_value, read_json
from qrfield.handeye.rigid import check_transform, make_transform
from qrfield.handeye.setups import EYE_IN_HAND, SETUPS, TARGET_FRAME, TRANSFORM_KEY, HandEyeError

FORMAT = "qrfield-handeye/1"
#: The file's name in the config folder (where ``$QRC,HANDEYE`` saves it, and ``frame`` looks).
FILE_NAME = "handeye.json"
#: The field that marks a calibration made from frames of a source that is not a live camera (the
#: virtual bench, a video, a folder): ``qrfield run`` refuses it with a live camera.
SIMULATED_KEY = "simulated"
#: What a file replaced by a new calibration is renamed to: ``handeye.json.previous``.
PREVIOUS_SUFFIX = ".previous"
#: How far from a rotation a file's matrix may be (rounded by hand) before it is refused.
ROTATION_TOLERANCE = 1e-3
#: The key of the code's place found with the transform.
OTHER_KEY = {EYE_IN_HAND: "code_in_base", "eye-to-hand": "code_in_tool"}


@dataclass(frozen=True)
class HandEyeCalibration:
    """A hand-eye calibration as saved in handeye.json.

    Attributes:
        setup: "eye-in-hand" or "eye-to-hand".
        transform: (4, 4) camera_to_tool or camera_to_base, mm.
        residual_mm, residual_deg: RMS residuals over the pairs (mm, deg).
        n_pairs: pairs solved from; method: how.
        covariance: (6, 6) of the transform's (dt mm, dtheta deg) in the tool/base frame, or None
            when the file has none (then poses carried through it keep only their own uncertainty).
        extra: the file's other fields, kept as read (pairs, camera, created, ...).
        path: the file it was read from, if any.
    """

    setup: str
    transform: np.ndarray
    residual_mm: float
    residual_deg: float
    n_pairs: int
    method: str
    covariance: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    @property
    def simulated(self) -> bool:
        """Made from frames of a source that is not a live camera (the file's ``simulated`` field)."""
        return self.extra.get(SIMULATED_KEY) is True

    @property
    def target_frame(self) -> str:
        """ "tool" (eye-in-hand) or "base" (eye-to-hand): where the transform maps camera coordinates."""
        return TARGET_FRAME[self.setup]

    @classmethod
    def from_result(cls, result: Any, **info: Any) -> HandEyeCalibration:
        """From a :class:`qrfield.handeye.HandEyeResult`; ``info``: more fields to save (camera, side_mm)."""
        extra = {
            "translation_std_mm": [float(v) for v in result.translation_std_mm],
            "rotation_std_deg": [float(v) for v in result.rotation_std_deg],
            "chi2": float(result.chi2),
            "dof": int(result.dof),
            "weighted": bool(result.weighted),
            OTHER_KEY[result.setup]: _rows(result.other),
            "pairs": [
                {"label": label, "residual_mm": float(mm), "residual_deg": float(deg)}
                for label, mm, deg in zip(
                    result.labels, result.residuals_mm, result.residuals_deg, strict=True
                )
            ],
            **info,
        }
        return cls(
            setup=result.setup,
            transform=np.array(result.transform, dtype=float),
            residual_mm=result.residual_mm,
            residual_deg=result.residual_deg,
            n_pairs=result.n_pairs,
            method=result.method,
            covariance=np.array(result.covariance, dtype=float),
            extra=extra,
        )

    def to_dict(self) -> dict[str, Any]:
        """The file's JSON object (the conventions' keys first)."""
        out: dict[str, Any] = {
            "setup": self.setup,
            TRANSFORM_KEY[self.setup]: _rows(self.transform),
            "residual_mm": float(self.residual_mm),
            "residual_deg": float(self.residual_deg),
            "n_pairs": int(self.n_pairs),
            "method": self.method,
            "format": FORMAT,
        }
        if self.covariance is not None:
            out["covariance"] = _rows(self.covariance)
        out.update({k: v for k, v in self.extra.items() if k not in out})
        out.setdefault("created", dt.datetime.now().astimezone().isoformat(timespec="seconds"))
        out.setdefault("qrfield_version", qrfield.__version__)
        return out

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the file all or nothing; returns its path."""
        return atomic_write_json(path, self.to_dict())

    @classmethod
    def from_dict(cls, data: Any, where: str, path: Path | None = None) -> HandEyeCalibration:
        """Read the fields; HandEyeError naming ``where`` and the field for anything wrong."""
        try:
            fields = Fields(data, where)
            setup = fields.text("setup")
            if setup not in SETUPS:
                raise HandEyeError(
                    f"{where}: field 'setup' must be one of {', '.join(SETUPS)}, got {setup!r}"
                )
            key = TRANSFORM_KEY[setup]
            transform = _transform(_matrix(fields, key, (4, 4), where), f"{where}: field '{key}'")
            covariance = None
            if "covariance" in data:
                covariance = _matrix(fields, "covariance", (6, 6), where)
                if not np.allclose(covariance, covariance.T, atol=1e-9) or np.any(np.diag(covariance) < 0):
                    raise HandEyeError(
                        f"{where}: field 'covariance' is not a covariance (symmetric, diagonal >= 0)"
                    )
            calibration = cls(
                setup=setup,
                transform=transform,
                residual_mm=fields.number("residual_mm"),
                residual_deg=fields.number("residual_deg"),
                n_pairs=fields.integer("n_pairs"),
                method=fields.text("method", ""),
                covariance=covariance,
                extra={k: v for k, v in data.items() if k not in _KNOWN},
                path=path,
            )
        except FileFormatError as exc:
            raise HandEyeError(str(exc)) from None
        return calibration

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> HandEyeCalibration:
        """Read handeye.json; HandEyeError (one line naming the file) if it cannot be used."""
        path = Path(path)
        try:
            data = read_json(path, "hand-eye file")
        except FileFormatError as exc:
            hint = (
                " (make one with `qrfield handeye PAIRS.csv ... --out FILE`)" if exc.kind == "missing" else ""
            )
            raise HandEyeError(f"{exc}{hint}") from None
        return cls.from_dict(data, f"hand-eye file {path}", path)


def simulated_path(path: str | os.PathLike[str]) -> Path:
    """Where a calibration from simulated frames is saved instead of ``path``: ``handeye.json`` ->
    ``handeye-simulated.json`` (never over the file a live camera's run reads)."""
    path = Path(path)
    return path.with_name(f"{path.stem}-simulated{path.suffix}")


def save_keeping_previous(calibration: HandEyeCalibration, path: str | os.PathLike[str]) -> Path | None:
    """Write ``calibration`` to ``path``; a file already there is kept as ``path.previous`` (the one
    before that is replaced), and put back if the new one cannot be written (the OSError is raised).
    Returns the kept file's path, or None when there was none."""
    path = Path(path)
    previous = path.with_name(path.name + PREVIOUS_SUFFIX)
    kept = None
    if path.is_file():
        os.replace(path, previous)
        kept = previous
    try:
        calibration.save(path)
    except BaseException:
        if kept is not None and not path.exists():
            os.replace(previous, path)
        raise
    return kept


_KNOWN = frozenset({"setup", "residual_mm", "residual_deg", "n_pairs", "method", "format", "covariance"})
_KNOWN = _KNOWN | frozenset(TRANSFORM_KEY.values())


def _rows(matrix: np.ndarray) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.asarray(matrix)]


def _matrix(fields: Fields, key: str, shape: tuple[int, int], where: str) -> np.ndarray:
    value = fields.data.get(key)
    if value is None:
        raise HandEyeError(f"{where}: missing field '{key}'")
    ok = isinstance(value, list) and len(value) == shape[0]
    ok = ok and all(isinstance(row, list) and len(row) == shape[1] for row in value)
    ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) for row in value for v in row)
    if not ok:
        raise HandEyeError(
            f"{where}: field '{key}' must be {shape[0]} rows of {shape[1]} numbers, "
            f"got {describe_value(value)}"
        )
    matrix = np.array(value, dtype=float)
    if not np.all(np.isfinite(matrix)):
        raise HandEyeError(f"{where}: field '{key}' must be finite")
    return matrix


def _transform(matrix: np.ndarray, where: str) -> np.ndarray:
    """A rigid transform from a matrix whose rotation may be rounded: made orthonormal again."""
    try:
        check_transform(matrix, where, tolerance=ROTATION_TOLERANCE)
    except ValueError as exc:
        raise HandEyeError(str(exc)) from None
    u, _, vt = np.linalg.svd(matrix[:3, :3])
    return make_transform(u @ vt, matrix[:3, 3])
