"""The real photos in ../shared/data/qr-photos (zxing-cpp's test images, each labelled with its text)."""

from __future__ import annotations

import cv2
import pytest

from qrfield.detect import Detector

#: Measured with the default settings: 75 of the 77 photos (zxing-cpp alone, unchecked: 74).
MIN_FOUND = 74
#: Photos that really hold more than one code: qrcode-2/16.png is a "double QR", an inner code
#: (the label) printed inside an outer one whose text reads "[outer QR code]".
SEVERAL_CODES = {"qrcode-2/16.png"}


@pytest.mark.slow
def test_real_photos(shared_data):
    root = shared_data / "qr-photos"
    photos = sorted(p for p in root.glob("*/*") if p.suffix in (".png", ".jpg"))
    assert len(photos) >= 77
    detector = Detector()
    found = 0
    for photo in photos:
        label = photo.with_suffix(".txt").read_bytes().decode("utf-8", errors="replace")  # keep \r\n
        image = cv2.imread(str(photo), cv2.IMREAD_COLOR)
        texts = [d.text for d in detector.detect(image)]
        name = photo.relative_to(root).as_posix()
        if name not in SEVERAL_CODES:
            assert all(t == label for t in texts), f"{name}: read {texts!r}, label {label!r}"
        found += label in texts
    assert found >= MIN_FOUND
