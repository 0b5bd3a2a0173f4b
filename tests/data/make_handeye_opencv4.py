"""Makes tests/data/handeye_opencv4.json: OpenCV 4.x's calibrateHandEye answers on fixed pair sets.

OpenCV 5's Python bindings (the version qrfield installs) lack calibrateHandEye; 4.x has it. This
script runs under a throwaway OpenCV 4 venv and records, for both set-ups, a seeded pair set (tool
poses T_base_tool, code poses T_camera_marker with noise drawn from a stated covariance, the true
transforms) and the answer of every method of cv2.calibrateHandEye. tests/test_handeye_opencv.py
reads the file; it installs nothing. It uses numpy and cv2 only (nothing of qrfield), so the pair
set does not come from the code under test.

    python3 -m venv /tmp/cv4 && /tmp/cv4/bin/pip install opencv-python-headless==4.11.0.86 numpy
    /tmp/cv4/bin/python tests/data/make_handeye_opencv4.py
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np

SEED = 20240528
PAIRS = 12
#: The code pose's noise, 1 sigma: x, y, z in mm, alpha, beta, gamma in degrees (a 50 mm code at
#: 300 mm measured by a 640x480 camera is about this good).
SIGMA = [0.03, 0.03, 0.1, 0.08, 0.08, 0.03]
METHODS = {
    "tsai": cv2.CALIB_HAND_EYE_TSAI,
    "park": cv2.CALIB_HAND_EYE_PARK,
    "horaud": cv2.CALIB_HAND_EYE_HORAUD,
    "andreff": cv2.CALIB_HAND_EYE_ANDREFF,
    "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
}


def euler(angles_deg):
    """R = Rx(a) Ry(b) Rz(g) (docs/conventions.md)."""
    a, b, g = np.radians(angles_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(g), -math.sin(g), 0], [math.sin(g), math.cos(g), 0], [0, 0, 1]])
    return rx @ ry @ rz


def euler_of(r):
    """alpha, beta, gamma in degrees of R (the conventions' extraction; no gimbal lock here)."""
    return np.degrees([math.atan2(-r[1, 2], r[2, 2]), math.asin(r[0, 2]), math.atan2(-r[0, 1], r[0, 0])])


def rigid(r, t):
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = r, t
    return out


def random_rigid(rng, max_deg, scale_mm):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    r = cv2.Rodrigues(axis * math.radians(rng.uniform(0, max_deg)))[0]
    return rigid(r, rng.normal(size=3) * scale_mm)


def pair_set(rng, setup):
    x = random_rigid(rng, 180, 60)  # camera_to_tool / camera_to_base
    y = random_rigid(rng, 180, 300)  # code in base / code in tool
    tools, codes = [], []
    for _ in range(PAIRS):
        tool = random_rigid(rng, 35, 150)
        m = np.linalg.inv(tool) if setup == "eye-in-hand" else tool
        true = np.linalg.inv(x) @ m @ y
        noise = rng.normal(size=6) * SIGMA
        code = rigid(euler(euler_of(true[:3, :3]) + noise[3:]), true[:3, 3] + noise[:3])
        tools.append(tool)
        codes.append(code)
    return x, y, tools, codes


def opencv_answers(setup, tools, codes):
    grip = tools if setup == "eye-in-hand" else [np.linalg.inv(t) for t in tools]
    out = {}
    for name, flag in METHODS.items():
        r, t = cv2.calibrateHandEye(
            [g[:3, :3] for g in grip],
            [g[:3, 3] for g in grip],
            [c[:3, :3] for c in codes],
            [c[:3, 3] for c in codes],
            method=flag,
        )
        out[name] = rigid(r, t.reshape(3)).tolist()
    return out


def main() -> None:
    rng = np.random.default_rng(SEED)
    sets = []
    for setup in ("eye-in-hand", "eye-to-hand"):
        x, y, tools, codes = pair_set(rng, setup)
        sets.append(
            {
                "setup": setup,
                "true_transform": x.tolist(),
                "true_other": y.tolist(),
                "tool_in_base": [t.tolist() for t in tools],
                "code_in_camera": [c.tolist() for c in codes],
                "code_sigma": SIGMA,
                "opencv": opencv_answers(setup, tools, codes),
                "opencv_exact": opencv_answers(
                    setup,
                    tools,
                    [
                        np.linalg.inv(x) @ (np.linalg.inv(t) if setup == "eye-in-hand" else t) @ y
                        for t in tools
                    ],
                ),
            }
        )
    data = {
        "made_by": "tests/data/make_handeye_opencv4.py",
        "opencv": cv2.__version__,
        "seed": SEED,
        "sigma_units": "x, y, z mm; alpha, beta, gamma deg (R = Rx Ry Rz)",
        "sets": sets,
    }
    path = Path(__file__).with_name("handeye_opencv4.json")
    path.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {path} (OpenCV {cv2.__version__})")


if __name__ == "__main__":
    main()
