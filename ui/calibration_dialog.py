"""The calibration dialog: capture chessboard views, see where the board has been, compute, save, use.

Frames come from the app's worker (the main window forwards each frame it draws; the dialog never
calls the camera) or, in *virtual chessboard* mode, from :class:`qrfield.virtual_board.VirtualChessboard`
rendering seeded board poses through the app's current camera model (so the dialog can be tried,
and tested, without hardware). The board finder, a :class:`ui.background.BackgroundJob` fed with
:meth:`~ui.background.BackgroundJob.submit`, runs :func:`qrfield.calibration.detect_board`
(``thorough=False`` for live frames) and draws the corners off the GUI thread, one frame at a
time: a frame arriving while it is busy replaces the waiting one (frames are dropped, never queued).
Saving writes the CameraModel JSON as ``NAME.json`` in the user's calib folder
(:func:`qrfield.paths.user_calib_dir`, never the checkout's shipped presets; no silent
overwrite), NAME being the camera name the operator gives; "Use" makes it the app's camera model.
:func:`qrfield.calibration.calibrate` runs as a :class:`ui.background.BackgroundJob`. The dialog
fits an 800x480 screen without scrolling: beside the picture, Capture view and Next pose over
three pages (Board: the settings; Views: the captured views and their coverage; Result: the
result, Save and Use), Compute and Close under them.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield import paths
from qrfield.calibration import (
    MIN_VIEWS,
    BoardDetection,
    CalibrationError,
    CalibrationResult,
    calibrate,
    coverage_grid,
    detect_board,
    uncovered_cells,
)
from qrfield.camera import CameraModel
from qrfield.chessboard import Board
from qrfield.files import make_folder
from qrfield.settings import setting
from qrfield.virtual_board import VirtualChessboard
from ui.background import BackgroundJob
from ui.settings_form import SettingsForm
from ui.text import short_path
from ui.touch import TouchCheckBox, answer, install_touch_style, yes_no

#: The pages beside the picture (in this order).
BOARD_PAGE, VIEWS_PAGE, RESULT_PAGE = range(3)
COVERED_COLOUR = "#2a8c2a"
UNCOVERED_COLOUR = "#c44"


@dataclass(frozen=True)
class CalibrationDialogSettings:
    """The dialog's choices, kept with the app's config."""

    board: str = setting(
        "9x6", label="board", help="inner corners COLSxROWS (OpenCV's pattern size), e.g. 9x6"
    )
    square_mm: float = setting(
        25.0,
        label="square side",
        unit="mm",
        minimum=0.1,
        maximum=1000.0,
        decimals=2,
        help="printed square side",
    )
    name: str = setting(
        "calibrated",
        label="camera name",
        help="saved as NAME.json in the user's calib folder (~/.config/qrfield/calib); "
        "the Camera tab then knows it by this name",
    )
    fix_k3: bool = setting(False, label="fix k3", help="keep k3 = 0 (few views, or a mild lens)")
    virtual_seed: int = setting(
        1, label="virtual seed", minimum=0, maximum=1_000_000, help="seed of the virtual chessboard's poses"
    )


@dataclass(frozen=True)
class BoardPreview:
    """One frame and the board found in it.

    Attributes:
        drawn: (H, W, 3) RGB uint8 picture with the detected corners drawn (OpenCV's colours).
        detection: the board's corners (OpenCV order and pixel convention) or the reason it was not found.
        board: the board searched for.
        source: ``live`` or ``virtual``.
        truth_px: for a virtual view, the exact corner pixels rendered (else None).
    """

    drawn: np.ndarray
    detection: BoardDetection
    board: Board
    source: str
    truth_px: np.ndarray | None = None


def make_preview(
    image: np.ndarray, board: Board, source: str, truth_px: np.ndarray | None = None
) -> BoardPreview:
    """Detect ``board`` in a grey or BGR uint8 ``image`` (quick detector for live frames) and draw it."""
    detection = detect_board(image, board, label=source, thorough=source != "live")
    if image.ndim == 2:
        rgb = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    else:
        rgb = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    if detection.found:
        corners = detection.corners_px.reshape(-1, 1, 2).astype(np.float32)
        cv2.drawChessboardCorners(rgb, board.pattern_size, corners, True)
    return BoardPreview(rgb, detection, board, source, truth_px)


class CalibrationDialog(QtWidgets.QDialog):
    """Capture views, compute, save and use a camera calibration.

    ``camera_provider`` returns the app's current camera model (rendered through in virtual mode).
    Emits ``cameraChosen(path)`` when the user presses Use.
    """

    cameraChosen = QtCore.Signal(str)
    computed = QtCore.Signal(object)  # shown: the CalibrationResult or an error message (str)

    def __init__(
        self,
        camera_provider: Callable[[], CameraModel],
        settings: CalibrationDialogSettings | None = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        install_touch_style()  # finger-sized controls, also when opened on its own
        self.setWindowTitle("qrfield — camera calibration")
        self._initial_settings = settings
        self.camera_provider = camera_provider
        self.captured: list[BoardDetection] = []
        #: per captured view, the exact corner pixels when it was rendered (virtual), else None
        self.captured_truth: list[np.ndarray | None] = []
        self.current: BoardPreview | None = None
        self.result: CalibrationResult | None = None
        self.saved_path: Path | None = None
        self.computing = False
        self._virtual: VirtualChessboard | None = None
        self._virtual_key: tuple[Any, ...] | None = None
        #: Finds and draws the board in the newest frame (newest replaces older: ``submit``).
        self.finder = BackgroundJob("calibration-preview", self)
        self.job = BackgroundJob("calibrate", self)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)  # 44 px rows: every pixel of an 800x480 screen counts
        layout.addLayout(self._build_picture(), 3)
        layout.addWidget(self._build_controls(), 2)
        self._fit_screen()
        self._wire()
        self._board = self._parse_board()
        self._seed = self.settings().virtual_seed
        self._update_coverage()
        self._update_path()

    # ---------------------------------------------------------------- builders
    def _build_picture(self) -> QtWidgets.QVBoxLayout:
        self.picture = QtWidgets.QLabel("waiting for frames…")
        self.picture.setObjectName("picture")
        self.picture.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self.picture.setMinimumSize(240, 180)
        self.picture.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Ignored)
        self.picture.setStyleSheet("background: #202020; color: #ccc;")
        self.found_label = QtWidgets.QLabel("")
        self.found_label.setObjectName("found")
        self.found_label.setWordWrap(True)
        left = QtWidgets.QVBoxLayout()
        left.addWidget(self.picture, 1)
        left.addWidget(self.found_label)
        return left

    def _build_controls(self) -> QtWidgets.QWidget:
        """Capture view and Next pose over three pages (Board | Views | Result), Compute and Close
        under them: on an 800x480 screen every button is in view and nothing scrolls but the views
        list and the result text. Capturing shows the Views page, a computed result the Result page."""
        self.form = SettingsForm(CalibrationDialogSettings, self._initial_settings)
        column = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(column)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(self._build_capture())
        self.pages = QtWidgets.QTabWidget()
        self.pages.setObjectName("calibration_pages")
        self.pages.addTab(self._build_board_page(), "Board")
        self.pages.addTab(self._build_views_page(), "Views")
        self.pages.addTab(self._build_result_page(), "Result")
        layout.addWidget(self.pages, 1)
        layout.addLayout(self._build_compute())
        return column

    def _build_capture(self) -> QtWidgets.QHBoxLayout:
        """Capture view and Next pose (the virtual chessboard's)."""
        self.next_button = QtWidgets.QPushButton("Next pose")
        self.next_button.setObjectName("next_pose")
        self.next_button.setEnabled(False)
        self.capture_button = QtWidgets.QPushButton("Capture view")
        self.capture_button.setObjectName("capture")
        self.capture_button.setEnabled(False)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.capture_button, 2)
        row.addWidget(self.next_button, 1)
        return row

    def _build_board_page(self) -> QtWidgets.QWidget:
        """The settings and the virtual chessboard switch."""
        self.virtual_check = TouchCheckBox("virtual chessboard")
        self.virtual_check.setToolTip("seeded board poses rendered through the app's camera model")
        self.virtual_check.setObjectName("virtual")
        policy = QtWidgets.QSizePolicy.Policy
        self.virtual_check.setSizePolicy(policy.Maximum, policy.Fixed)  # a click beside the text does nothing
        page = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(page)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.setSpacing(2)
        layout.addWidget(self.form)
        layout.addWidget(self.virtual_check)
        layout.addStretch(1)
        return page

    def _build_views_page(self) -> QtWidgets.QWidget:
        """The captured views' list (it scrolls) with Remove view and Clear views, and the coverage."""
        self.views = QtWidgets.QListWidget()
        self.views.setObjectName("views")
        self.views.setMinimumHeight(60)
        self.remove_button = QtWidgets.QPushButton("Remove view")
        self.remove_button.setObjectName("remove_view")
        self.clear_button = QtWidgets.QPushButton("Clear views")
        self.clear_button.setObjectName("clear_views")
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.remove_button)
        row.addWidget(self.clear_button)
        page = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(page)
        layout.addWidget(self.views, 1)
        layout.addLayout(row)
        layout.addWidget(self._build_coverage())
        return page

    def _build_compute(self) -> QtWidgets.QHBoxLayout:
        """Compute and Close."""
        self.compute_button = QtWidgets.QPushButton(f"Compute (needs {MIN_VIEWS} views)")
        self.compute_button.setObjectName("compute")
        self.compute_button.setEnabled(False)
        self.close_button = QtWidgets.QPushButton("Close")
        self.close_button.setObjectName("close")
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.compute_button, 2)
        row.addWidget(self.close_button, 1)
        return row

    def _build_result_page(self) -> QtWidgets.QWidget:
        """The result's text (it scrolls), where Save writes, Save and Use, and the note line."""
        self.results = QtWidgets.QPlainTextEdit()
        self.results.setObjectName("results")
        self.results.setReadOnly(True)
        self.results.setPlaceholderText("Compute shows the calibration here")
        self.path_label = QtWidgets.QLabel("")
        self.path_label.setWordWrap(True)
        self.save_button = QtWidgets.QPushButton("Save")
        self.save_button.setObjectName("save")
        self.use_button = QtWidgets.QPushButton("Use")
        self.use_button.setObjectName("use")
        self.use_button.setToolTip("save (if not yet saved) and make it the app's camera model")
        for button in (self.save_button, self.use_button):
            button.setEnabled(False)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.save_button)
        row.addWidget(self.use_button)
        self.note = QtWidgets.QLabel("")
        self.note.setObjectName("note")
        self.note.setWordWrap(True)
        page = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(page)
        layout.addWidget(self.results, 1)
        layout.addWidget(self.path_label)
        layout.addLayout(row)
        layout.addWidget(self.note)
        return page

    def _build_coverage(self) -> QtWidgets.QGroupBox:
        box = QtWidgets.QGroupBox("views per image cell")
        box.setToolTip("where the board has been: captured views with a corner in each ninth of the image")
        layout = QtWidgets.QVBoxLayout(box)
        grid = QtWidgets.QGridLayout()
        grid.setSpacing(2)
        self.cells: list[list[QtWidgets.QLabel]] = []
        for r in range(3):
            row_labels = []
            for c in range(3):
                label = QtWidgets.QLabel("0")
                label.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
                label.setMinimumSize(44, 26)
                grid.addWidget(label, r, c)
                row_labels.append(label)
            self.cells.append(row_labels)
        layout.addLayout(grid)
        self.hint = QtWidgets.QLabel("")
        self.hint.setObjectName("hint")
        self.hint.setWordWrap(True)
        layout.addWidget(self.hint)
        return box

    def _fit_screen(self) -> None:
        """1100x820, or the screen's free area when that is smaller (an 800x480 display)."""
        screen = self.screen() or QtWidgets.QApplication.primaryScreen()
        free = screen.availableGeometry() if screen is not None else QtCore.QRect(0, 0, 1100, 820)
        self.resize(min(1100, free.width()), min(820, free.height()))

    def _wire(self) -> None:
        self.finder.finished.connect(self._on_preview)
        self.finder.failed.connect(lambda text: self.note.setText(f"⚠ preview: {text}"))
        self.job.finished.connect(self._on_computed)
        self.job.failed.connect(lambda text: self._on_computed(f"calibration failed: {text}"))
        self.form.changed.connect(self._on_settings_changed)
        self.virtual_check.toggled.connect(self._on_virtual_toggled)
        self.next_button.clicked.connect(self.request_virtual_view)
        self.capture_button.clicked.connect(self.capture)
        self.remove_button.clicked.connect(self._remove_selected)
        self.clear_button.clicked.connect(self.clear_views)
        self.compute_button.clicked.connect(self.compute)
        self.save_button.clicked.connect(self.save)
        self.use_button.clicked.connect(self.use)
        self.close_button.clicked.connect(self.close)

    # ---------------------------------------------------------------- settings
    def settings(self) -> CalibrationDialogSettings:
        return self.form.value()

    def board(self) -> Board | None:
        """The board the inputs describe, or None (the reason is shown) when they are malformed."""
        return self._board

    def _parse_board(self) -> Board | None:
        s = self.settings()
        try:
            board = Board.parse(s.board, s.square_mm)
        except ValueError as exc:
            self.found_label.setText(f"⚠ {exc}")
            return None
        return board

    def _on_settings_changed(self, *_: object) -> None:
        old_key = (self._board, self._seed)
        board = self._parse_board()
        self._seed = self.settings().virtual_seed
        if board is not None and self._board is not None and board.pattern_size != self._board.pattern_size:
            if self.captured:
                self.note.setText(f"{len(self.captured)} views of the {self._board.label} board cleared")
            self.clear_views()
        self._board = board
        self._update_path()
        self._update_capture()
        if self.virtual_check.isChecked() and (board, self._seed) != old_key:
            self.request_virtual_view()

    def save_path(self) -> Path:
        """Where Save writes: ``NAME.json`` in the user's calib folder
        (:func:`qrfield.paths.user_calib_dir`, where camera names are looked up), NAME being the
        camera name given, made file-safe."""
        return paths.user_calib_dir() / f"{profile_name(self.settings().name)}.json"

    def _update_path(self) -> None:
        self.path_label.setText(f"saves to {_shown_path(self.save_path())}")

    # ---------------------------------------------------------------- frames in
    def on_frame(self, image: np.ndarray) -> None:
        """A frame the app drew (GUI thread): the finder detects the board in it off the GUI thread (a
        frame still waiting when the next one comes is replaced)."""
        if self.virtual_check.isChecked() or not self.isVisible() or self._board is None:
            return
        board = self._board
        image = np.ascontiguousarray(image)
        self.finder.submit(make_preview, image, board, "live")

    def _on_virtual_toggled(self, on: bool) -> None:
        self.next_button.setEnabled(on)
        if self.captured:
            self.note.setText(f"{len(self.captured)} views from the other source cleared")
        self.clear_views()
        self.current = None
        self._update_capture()
        if on:
            self.request_virtual_view()

    def _virtual_board(self, board: Board) -> VirtualChessboard:
        camera = self.camera_provider()
        key = (camera, board, self.settings().virtual_seed)
        if self._virtual is None or self._virtual_key != key:
            self._virtual = VirtualChessboard(camera, board, self.settings().virtual_seed)
            self._virtual_key = key
        return self._virtual

    def request_virtual_view(self) -> None:
        """Render the virtual chessboard at its next seeded pose (in the finder's run)."""
        if not self.virtual_check.isChecked() or self._board is None:
            return
        board = self._board
        try:
            virtual = self._virtual_board(board)
        except ValueError as exc:
            self.found_label.setText(f"⚠ virtual chessboard: {exc}")
            return

        def job() -> BoardPreview:
            view = virtual.next_view()
            return make_preview(view.image, board, "virtual", view.corners_px)

        self.current = None
        self._update_capture()
        self.finder.submit(job)

    def _on_preview(self, preview: BoardPreview) -> None:
        if preview.board != self._board or (preview.source == "virtual") != self.virtual_check.isChecked():
            return  # made for settings no longer shown
        self.current = preview
        rgb = preview.drawn
        h, w = rgb.shape[:2]
        image = QtGui.QImage(rgb.data, w, h, 3 * w, QtGui.QImage.Format.Format_RGB888).copy()
        self._pixmap = QtGui.QPixmap.fromImage(image)
        self._show_pixmap()
        d = preview.detection
        self.found_label.setText(
            f"board {preview.board.label} found ({d.method}), {w}x{h} px" if d.found else f"{d.reason}"
        )
        self.found_label.setStyleSheet(f"color: {COVERED_COLOUR if d.found else UNCOVERED_COLOUR};")
        self._update_capture()

    def _show_pixmap(self) -> None:
        pixmap = getattr(self, "_pixmap", None)
        if pixmap is not None:
            self.picture.setPixmap(
                pixmap.scaled(
                    self.picture.size(),
                    QtCore.Qt.AspectRatioMode.KeepAspectRatio,
                    QtCore.Qt.TransformationMode.SmoothTransformation,
                )
            )

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:
        super().resizeEvent(event)
        self._show_pixmap()

    # ---------------------------------------------------------------- views
    def _update_capture(self) -> None:
        ok = self.current is not None and self.current.detection.found and self.current.board == self._board
        self.capture_button.setEnabled(bool(ok))
        self.compute_button.setEnabled(len(self.captured) >= MIN_VIEWS and not self.computing)
        self.compute_button.setText(
            "Compute" if len(self.captured) >= MIN_VIEWS else f"Compute (needs {MIN_VIEWS} views)"
        )

    def capture(self) -> None:
        """Keep the shown frame's detection as a view (then, in virtual mode, show the next pose)."""
        preview = self.current
        if preview is None or not preview.detection.found or preview.board != self._board:
            return
        label = f"view {len(self.captured) + 1}"
        d = preview.detection
        self.captured.append(dataclasses.replace(d, label=label))
        self.captured_truth.append(preview.truth_px)
        self.views.addItem(f"{label}: {d.image_size[0]}x{d.image_size[1]} px ({preview.source})")
        self.current = None  # the same frame is not captured twice
        self._views_changed()
        self.pages.setCurrentIndex(VIEWS_PAGE)  # the new view in the list, and where it counts
        if self.virtual_check.isChecked():
            self.request_virtual_view()

    def _remove_selected(self) -> None:
        row = self.views.currentRow()
        if 0 <= row < len(self.captured):
            del self.captured[row]
            del self.captured_truth[row]
            self.views.takeItem(row)
            self._views_changed()

    def clear_views(self) -> None:
        self.captured.clear()
        self.captured_truth.clear()
        self.views.clear()
        self._views_changed()

    def _views_changed(self) -> None:
        self.result = None
        self.saved_path = None
        self.save_button.setEnabled(False)
        self.use_button.setEnabled(False)
        self._update_coverage()
        self._update_capture()

    def coverage(self) -> np.ndarray:
        """(3, 3) int array: captured views with a corner in each image cell (rows top to bottom)."""
        if not self.captured:
            return np.zeros((3, 3), dtype=int)
        size = self.captured[-1].image_size
        return coverage_grid([d.corners_px for d in self.captured if d.image_size == size], size, (3, 3))

    def _update_coverage(self) -> None:
        grid = self.coverage()
        for r in range(3):
            for c in range(3):
                n = int(grid[r, c])
                label = self.cells[r][c]
                label.setText(str(n))
                colour = COVERED_COLOUR if n else UNCOVERED_COLOUR
                label.setStyleSheet(f"background: {colour}; color: white; font-weight: bold;")
        missing = uncovered_cells(grid)
        if not self.captured:
            self.hint.setText(
                "capture views with the board in every part of the image, tilted different ways"
            )
        elif missing:
            self.hint.setText("not yet covered: " + ", ".join(missing))
        else:
            self.hint.setText("every cell covered")

    # ---------------------------------------------------------------- compute
    def compute(self) -> None:
        """Calibrate from the captured views in the background; ``computed`` once the result is shown."""
        board = self._board
        if self.computing or board is None or len(self.captured) < MIN_VIEWS:
            return
        self.computing = True
        self._update_capture()
        self.results.setPlainText(f"computing from {len(self.captured)} views…")
        self.pages.setCurrentIndex(RESULT_PAGE)
        detections = list(self.captured)
        s = self.settings()
        name = s.name.strip() or "calibrated"
        stream = self.camera_provider()  # its sensor crop and lens position go into the profile

        def work() -> Any:
            try:
                return calibrate(detections, board, fix_k3=s.fix_k3, name=name, stream=stream)
            except CalibrationError as exc:
                return f"calibration failed: {exc}"

        self.job.start(work)

    def _on_computed(self, outcome: Any) -> None:
        self.computing = False
        self._update_capture()
        if isinstance(outcome, str):
            self.result = None
            self.results.setPlainText(outcome)
            self.computed.emit(outcome)
            return
        self.result = outcome
        self.saved_path = None
        self.results.setPlainText(describe(outcome))
        errors = {v.label: v for v in outcome.views}
        for row, d in enumerate(self.captured):
            item = self.views.item(row)
            view = errors.get(d.label)
            base = item.text().split("  →")[0]
            item.setText(f"{base}  → {view.rms_px:.3f} px RMS" if view else f"{base}  → skipped")
        self.save_button.setEnabled(True)
        self.use_button.setEnabled(True)
        self.computed.emit(outcome)

    # ---------------------------------------------------------------- save / use
    def confirm_overwrite(self, path: Path) -> bool:
        """Ask before replacing an existing file (tests replace this method)."""
        return answer(*yes_no(self, "Overwrite?", f"{path} exists. Replace it?"), "no") == "yes"

    def save(self) -> Path | None:
        """Write the computed camera model to :meth:`save_path`; None when not saved (the note says why)."""
        if self.result is None:
            self.note.setText("compute first")
            return None
        path = self.save_path()
        if path.exists() and not self.confirm_overwrite(path):
            self.note.setText(f"not saved: {_shown_path(path)} exists")
            return None
        try:
            make_folder(path.parent, "profile folder")
            # All or nothing (qrfield.files.atomic_write): a failed write never leaves a truncated
            # model in place of the one the app may be using.
            self.result.camera.save(path)
        except OSError as exc:
            self.note.setText(f"⚠ not saved: {exc}")
            return None
        self.saved_path = path
        self.note.setText(f"saved {_shown_path(path)}")
        return path

    def use(self) -> None:
        """Save if needed, then make the model the app's camera (``cameraChosen``)."""
        path = self.saved_path or self.save()
        if path is None:
            return
        self.cameraChosen.emit(str(path))
        self.note.setText(f"the app now uses {_shown_path(path)}")

    # ---------------------------------------------------------------- shutdown
    def shutdown(self) -> None:
        self.finder.cancel()
        self.finder.join(5.0)
        self.job.join(5.0)

    def showEvent(self, event: QtGui.QShowEvent) -> None:
        super().showEvent(event)
        if self.virtual_check.isChecked() and self.current is None:
            self.request_virtual_view()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:
        self.current = None
        super().closeEvent(event)


def profile_name(name: str) -> str:
    """A camera name as a file name: letters, digits, '.', '_', '-'; other runs become '-'."""
    cleaned = re.sub(r"[^A-Za-z0-9._-]+", "-", name.strip()).strip("-.")
    return cleaned[:60] or "calibrated"


def _shown_path(path: Path) -> str:
    """``path`` with the home folder as ``~`` (shorter to read)."""
    return short_path(path)


def describe(result: CalibrationResult) -> str:
    """The result as text: RMS, intrinsics with their one-sigma uncertainty, per-view errors, advice."""
    cam, std = result.camera, result.std_px
    lines = [
        f"RMS reprojection error {result.rms_px:.3f} px over {len(result.views)} views "
        f"({cam.width}x{cam.height} px, board {result.board.label}, {result.board.square_mm:g} mm squares)",
        f"fx = {cam.fx:.2f} ± {std['fx']:.2f} px    fy = {cam.fy:.2f} ± {std['fy']:.2f} px",
        f"cx = {cam.cx:.2f} ± {std['cx']:.2f} px    cy = {cam.cy:.2f} ± {std['cy']:.2f} px",
        "dist (k1, k2, p1, p2, k3) = " + ", ".join(f"{d:.4g}" for d in cam.dist),
        "per view (RMS / largest, px): "
        + "; ".join(f"{v.label} {v.rms_px:.3f} / {v.max_px:.3f}" for v in result.views),
    ]
    lines += [f"skipped {s.label}: {s.reason}" for s in result.skipped]
    advice = result.advice()
    lines += [f"advice: {a}" for a in advice] if advice else ["advice: none, the calibration looks sound"]
    return "\n".join(lines)
