"""A folder of still images, read in sorted file-name order (unreadable files reported and skipped),
or one image file (``--source photo.png``: through :func:`qrfield.images.read_image`, so the pixel
limit, the PNG inflation cap and the one-line reasons hold, not through a video decoder)."""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

from qrfield.images import IMAGE_SUFFIXES, ImageError, read_image
from qrfield.sources.base import EndOfStream, Frame, FrameSource, Pacer, SourceError

log = logging.getLogger(__name__)


def is_image_file(path: Path) -> bool:
    """A regular file whose name ends in one of the image suffixes (``.png``, ``.jpg``, ...)."""
    return path.suffix.lower() in IMAGE_SUFFIXES and path.is_file()


class ImageFolderSource(FrameSource):
    """Every image file of a folder (not its sub-folders), sorted by name; or one image file
    (``path`` a file whose name ends in one of :data:`qrfield.images.IMAGE_SUFFIXES`).

    Files that OpenCV cannot read are skipped; each is reported once in ``notes`` and ``skipped``
    and logged as a warning. When no file is readable the source raises SourceError.

    Args:
        path: the folder.
        loop: start again at the first image at the end instead of raising EndOfStream.
        fps: deliver at most this many images per second (0 = as fast as read).
    """

    name = "folder"
    live = False  # an image is loaded when read(): every image in turn, none dropped

    def __init__(self, path: str | os.PathLike[str], loop: bool = False, fps: float = 0.0) -> None:
        super().__init__()
        self.path = Path(path)
        self.loop = loop
        self.files: list[Path] = []
        self.skipped: list[Path] = []
        self._pacer = Pacer(fps)
        self._position = 0

    @property
    def description(self) -> str:
        if is_image_file(self.path):
            return f"image {self.path}" + (" (looping)" if self.loop else "")
        return f"folder {self.path} ({len(self.files)} images)" + (" (looping)" if self.loop else "")

    @property
    def _what(self) -> str:
        return f"image {self.path}" if is_image_file(self.path) else f"image folder {self.path}"

    def _open_impl(self) -> None:
        if is_image_file(self.path):
            self.files, self._position, self.skipped = [self.path], 0, []
            return
        if not self.path.is_dir():
            raise SourceError(f"image folder {self.path}: no such folder")
        self.files = sorted(
            p for p in self.path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
        )
        if not self.files:
            raise SourceError(f"image folder {self.path}: no image files ({', '.join(IMAGE_SUFFIXES)})")
        self._position = 0
        self.skipped = []

    def _read_impl(self, index: int) -> Frame:
        self._pacer.wait()
        tried = 0
        while tried < len(self.files):
            if self._position >= len(self.files):
                if not self.loop:
                    raise EndOfStream(f"{self._what}: end after {len(self.files)} files")
                self._position = 0
            path = self.files[self._position]
            self._position += 1
            tried += 1
            if path in self.skipped:
                continue
            # ANYCOLOR keeps grey images grey; without ANYDEPTH, 16-bit files come back as 8-bit.
            # qrfield.images reads the size from the header first: an image above the pixel limit
            # is skipped before it is decoded.
            try:
                image = read_image(path, mode="any")
            except ImageError as exc:
                image, why = None, str(exc).removeprefix(f"{path}: ")
            if image is None and is_image_file(self.path):
                raise SourceError(f"image {path}: {why}")
            if image is None:
                self.skipped.append(path)
                message = f"skipped {path.name}: {why}"
                self.notes.append(message)
                log.warning("%s: %s", self.path, message)
                continue
            return Frame(image, time.monotonic(), index, label=path.name)
        if len(self.skipped) == len(self.files):
            raise SourceError(
                f"image folder {self.path}: none of its {len(self.files)} image files is readable"
            )
        raise EndOfStream(f"{self._what}: end after {len(self.files)} files")

    def _close_impl(self) -> None:
        pass
