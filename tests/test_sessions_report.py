"""A session's report.html: its numbers against rows of known errors, its figures embedded and
nothing referenced outside the page, the simulation's prediction against OpenCV's own IPPE on the
same rounded corners, and the page in a real headless Chromium (Debian's ``chromium``; skipped with
the reason where it is absent): it draws, and every image loads."""

from __future__ import annotations

import base64
import html.parser
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from qrfield.camera import CameraModel, resolve_camera
from qrfield.geometry import marker_vertices, rotation_matrix, rotation_to_ippe
from qrfield.sessions import GroundTruth, Session, measure
from qrfield.sessions.plan import generate_plan
from qrfield.sessions.progress import attach_plan
from qrfield.sessions.report import CSP, build_report, write_report
from qrfield.simulation.targets import NoiseModel, predict_poses

CAMERA = resolve_camera("picam-v2@640x480")
SIDE = 50.0
PLAN = generate_plan("alpha,beta+gamma-", [10, 30], z_mm=300)  # 4 targets
#: Measured minus truth of each row (mm, deg): rows 1, 2 and 4 pass, row 3 fails on beta (2.5 deg).
OFFSETS = [
    (0.5, 0, 0, 0.2, 0, 0),
    (0, -1.0, 0, 0, 0, 1.0),
    (0, 0, 2.0, 0, 2.5, 0),
    (0, 0, -1.0, -0.5, 0, 0),
]


class Page(html.parser.HTMLParser):
    """Every tag with its attributes, and the text."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict[str, str]]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, {k: v or "" for k, v in attrs}))

    def handle_data(self, data):
        self.text.append(data)


def parse(page: str) -> Page:
    parser = Page()
    parser.feed(page)
    return parser


def log_rows(session: Session, progress, sigma: float = 0.1) -> None:
    for target, offset in zip(PLAN, OFFSETS, strict=True):
        progress.will_log(target.number, session.next_row)
        t = target.truth
        frame = {
            "converged": True,
            "position_mm": np.add(t.position_mm, offset[:3]),
            "angles_deg": np.add(t.angles_deg, offset[3:]),
            "position_std_mm": [sigma] * 3,
            "angles_std_deg": [sigma] * 3,
        }
        session.log(measure([frame, frame], t, session.info.criteria, method="numerical"))


@pytest.fixture
def session_dir(tmp_path: Path) -> Path:
    session = Session.create(
        tmp_path, "report test", camera=CAMERA, side_mm=SIDE, solver="numerical", notes="jig <B>"
    )
    log_rows(session, attach_plan(session.path, PLAN, session.rows))
    session.close()
    return session.path


def test_the_report_states_the_rows_pass_rates_and_settings(session_dir: Path) -> None:
    summary = write_report(session_dir)
    assert summary.path == session_dir / "report.html"
    page = summary.path.read_text(encoding="utf-8")
    assert (summary.rows, summary.passed, summary.withdrawn) == (4, 3, 0)
    text = " ".join(parse(page).text)
    assert "3 of 4 rows pass" in text
    assert "jig <B>" in text and "<B>" not in page  # the notes, escaped
    assert "picam-v2@640x480" in text and "fx 529.62" in text and "50 mm" in text
    # The pass-rate table: alpha 10 and 30 pass; beta+gamma- at 10 fails, at 30 passes.
    rows = re.findall(r"<tr><th>([^<]+)</th>(.*?)</tr>", page)
    table = {name: re.findall(r">(\d+/\d+)", cells) for name, cells in rows}
    assert table["alpha"] == ["1/1", "1/1", "2/2"]
    assert table["beta+gamma-"] == ["0/1", "1/1", "1/2"]
    assert table["all"] == ["1/2", "2/2", "3/4"]
    # Each row with its uncertainty (the per-frame sigma logged: 0.1).
    assert page.count("± 0.100") == 4 * 6
    assert "Every target of the plan has a row" in text


def test_the_page_is_self_contained(session_dir: Path) -> None:
    page, summary = build_report(session_dir)
    parsed = parse(page)
    metas = [a for t, a in parsed.tags if t == "meta" and a.get("http-equiv") == "Content-Security-Policy"]
    assert metas and metas[0]["content"] == CSP and "default-src 'none'" in CSP
    images = [a for t, a in parsed.tags if t == "img"]
    assert len(images) == summary.images == 2
    for attrs in images:
        assert attrs["src"].startswith("data:image/png;base64,")
        png = base64.b64decode(attrs["src"].split(",", 1)[1], validate=True)
        image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        assert image is not None and image.shape[:2] == (int(attrs["height"]), int(attrs["width"]))
        assert image.std() > 10  # a figure, not a blank canvas
    for tag, attrs in parsed.tags:
        for name in ("src", "href", "srcset", "action", "data", "poster"):
            if name in attrs:
                assert attrs[name].startswith("data:"), (tag, name, attrs[name][:60])
        assert tag not in ("script", "link", "iframe", "object", "embed")
    assert not re.search(r"url\(|@import|https?:|//[a-z]", page.split("<body>", 1)[0].lower())


def test_withdrawn_rows_are_named_not_counted_and_a_session_without_plan_or_rows_reports(
    tmp_path: Path,
) -> None:
    session = Session.create(tmp_path, "empty", camera=CAMERA, side_mm=SIDE, solver="ippe")
    summary = write_report(session.path)
    assert summary.rows == 0 and summary.images == 2
    assert "No rows yet" in summary.path.read_text(encoding="utf-8")
    truth = GroundTruth(0, 0, 300, 10, 0, 0, "alpha")
    frame = {"converged": True, "position_mm": truth.position_mm, "angles_deg": truth.angles_deg}
    session.log(measure([frame], truth))
    session.log(measure([frame], truth))
    session.undo()
    session.close()
    summary = write_report(session.path, tmp_path / "elsewhere.html")
    assert (summary.rows, summary.withdrawn) == (1, 1) and summary.path == tmp_path / "elsewhere.html"
    page = summary.path.read_text(encoding="utf-8")
    assert "Withdrawn (not counted): row(s) 2" in page and "1 withdrawn row(s) not counted" in page


# ------------------------------------------------------------------------------------ prediction
def test_exact_corners_predict_a_pass_and_a_card_turned_away_is_out_of_view() -> None:
    from qrfield.solvers import NumericalSettings

    position = [[0, 0, 300], [20, -10, 350], [0, 0, 300]]
    angles = [[10, 0, 0], [0, 30, -30], [0, 89, 0]]  # the last: seen edge-on, beyond 85 deg
    p = predict_poses(
        position, angles, CAMERA, SIDE, "numerical", NumericalSettings(), _criteria(), NoiseModel()
    )
    assert p.draws == 1 and list(p.in_view) == [True, True, False]
    assert list(p.passed[:, 0]) == [True, True, False]
    assert np.all(p.position_error_mm[:2] < 1e-3) and math.isnan(p.position_error_mm[2, 0])
    assert math.isnan(p.pass_share[2]) and p.pass_share[0] == 1.0


def test_the_prediction_with_rounded_corners_is_opencvs_ippe_on_the_same_corners() -> None:
    from qrfield.solvers import IppeSettings

    camera = CameraModel.from_focal(800.0, 1280, 960, name="wide")
    rng = np.random.default_rng(3)
    n = 30
    position = np.column_stack([rng.uniform(-60, 60, n), rng.uniform(-40, 40, n), rng.uniform(250, 600, n)])
    angles = rng.uniform(-35, 35, (n, 3))
    p = predict_poses(
        position, angles, camera, SIDE, "ippe", IppeSettings(refine="none"), _criteria(), NoiseModel("round")
    )
    assert p.in_view.all()
    k = np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1.0]])
    # Our vertices V1..V4 in the frame IPPE_SQUARE wants (+Y up, +Z towards the camera).
    square = marker_vertices(SIDE) * np.array([1.0, -1.0, -1.0])
    for i in range(n):
        rvec, _ = cv2.Rodrigues(rotation_to_ippe(rotation_matrix(angles[i])))
        corners, _ = cv2.projectPoints(square, rvec, position[i], k, None)
        rounded = np.round(corners.reshape(4, 2))
        ok, _rvec, tv = cv2.solvePnP(square, rounded, k, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        assert ok
        assert p.position_error_mm[i, 0] == pytest.approx(np.linalg.norm(tv.ravel() - position[i]), abs=1e-4)


def test_more_corner_noise_predicts_fewer_passes() -> None:
    from qrfield.solvers import NumericalSettings

    position, angles = [[0, 0, 400]] * 3, [[20, 0, 0], [0, 30, 0], [15, 15, 15]]
    shares = [
        predict_poses(
            position, angles, CAMERA, SIDE, "numerical", NumericalSettings(), _criteria(),
            NoiseModel("noise", px, 1), draws=300,
        ).pass_share.mean()
        for px in (0.05, 0.5, 2.0)
    ]  # fmt: skip
    assert shares[0] > shares[1] > shares[2] and shares[0] > 0.9 and shares[2] < 0.5


def _criteria():
    from qrfield.sessions.criteria import AcceptanceCriteria

    return AcceptanceCriteria()


@pytest.mark.slow
def test_the_command_prints_the_summary_and_uses_the_studys_noise(session_dir: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "qrfield", "report", str(session_dir), "--set", "degradation=round"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert "4 rows, 3 pass (75.0 %)" in done.stdout and "corners rounded to whole pixels" in done.stdout
    assert f"wrote {session_dir / 'report.html'}" in done.stdout
    page = (session_dir / "report.html").read_text(encoding="utf-8")
    assert "corners rounded to whole pixels" in page


# ------------------------------------------------------------------------------------ a browser
def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("no headless Chromium (Debian: apt-get install chromium); the browser check needs one")


def run_browser(browser: str, profile: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
            "--no-first-run", "--disable-extensions", f"--user-data-dir={profile}", *args,
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )  # fmt: skip


@pytest.mark.slow
def test_a_real_browser_draws_the_page_and_loads_every_image(session_dir: Path, tmp_path: Path) -> None:
    browser = chromium()
    report = write_report(session_dir).path
    # A copy with a script that counts the images loaded (the report itself has no script, and its
    # policy would block one: the copy allows inline scripts and keeps img-src data: only).
    page = report.read_text(encoding="utf-8")
    probe = (
        "<script>window.addEventListener('load', () => { const imgs = [...document.images];"
        "document.body.setAttribute('data-images', imgs.length);"
        "const loaded = imgs.filter(i => i.complete && i.naturalWidth > 0);"
        "document.body.setAttribute('data-loaded', loaded.length);"
        "document.body.setAttribute('data-width', Math.min(...imgs.map(i => i.naturalWidth))); });</script>"
    )
    checked = tmp_path / "checked.html"
    checked.write_text(
        page.replace(CSP, CSP + "; script-src 'unsafe-inline'").replace("</body>", probe + "</body>"),
        encoding="utf-8",
    )
    done = run_browser(
        browser, tmp_path / "profile-1", "--virtual-time-budget=10000", "--dump-dom", checked.as_uri()
    )
    assert done.returncode == 0, done.stderr[-2000:]
    body = re.search(r"<body([^>]*)>", done.stdout)
    assert body is not None, done.stdout[:500]
    attrs = dict(re.findall(r'data-(\w+)="(\d+)"', body.group(1)))
    assert attrs.get("images") == "2" and attrs.get("loaded") == "2", body.group(1)
    assert int(attrs["width"]) >= 800
    # The page itself, unchanged, drawn to a picture: not blank, and its figures' colours are in it.
    shot = tmp_path / "page.png"
    done = run_browser(
        browser, tmp_path / "profile-2", "--window-size=1200,2400", f"--screenshot={shot}", report.as_uri()
    )
    assert done.returncode == 0 and shot.exists(), done.stderr[-2000:]
    image = cv2.imread(str(shot))
    assert image is not None and image.shape[:2] == (2400, 1200)
    assert image.std() > 20
    green = np.all(np.abs(image.astype(int) - (115, 158, 0)) < 30, axis=-1)  # the figures' pass colour
    assert np.count_nonzero(green) > 50
