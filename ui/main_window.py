"""The bench app's main window: preview, pose panel, the control tabs (right) and, under the
preview, the live plots and the Session, Analysis and Simulation tabs.

The window never touches the camera: a :class:`~ui.worker.PipelineWorker` on its own QThread
captures and processes; the window takes the newest result on a QTimer (older unread results are
dropped, never queued) and redraws. Every change of a control becomes a new worker configuration
and is saved to the config file when the window closes.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.camera import DEFAULT_CAMERA, CameraModel, CameraModelError, resolve_camera
from qrfield.methods import methods_from_choice, settings_classes
from qrfield.runconfig import ConfigStore, RunConfig, RunSettings
from qrfield.serial_link import SerialLinkSettings
from qrfield.sources import Picamera2Settings, VirtualBenchSettings
from ui.analysis_tab import AnalysisTab
from ui.calibration_dialog import CalibrationDialog, CalibrationDialogSettings
from ui.controls import (
    CameraControls,
    SolverControls,
    SourceControls,
    ViewSettings,
    app_settings_from,
    show_app_settings,
    show_view_settings,
    view_settings_from,
)
from ui.plots import PosePlots
from ui.pose_panel import PosePanel
from ui.preview import PreviewView
from ui.serial_panel import SerialPanel
from ui.sessions_panel import BenchContext, SessionPanel
from ui.settings_form import SettingsForm
from ui.simulation_tab import CONFIG_KEY as SIMULATION_KEY
from ui.simulation_tab import SimulationTab
from ui.worker import PipelineWorker, Processed, start_worker, stop_worker

#: Redraw period of the GUI timer, ms (40 Hz, above the usual camera rate); plots redraw at most
#: every PLOT_PERIOD_S seconds.
REDRAW_MS = 25
PLOT_PERIOD_S = 0.2


def detector_settings_class() -> type:
    from qrfield.detect import DetectorSettings

    return DetectorSettings


class MainWindow(QtWidgets.QMainWindow):
    """The bench app. ``overrides`` (from the command line) replace saved RunSettings fields."""

    #: Each frame drawn (its image, grey or BGR uint8), for the calibration dialog's preview.
    frameDrawn = QtCore.Signal(object)

    def __init__(
        self,
        store: ConfigStore,
        overrides: dict[str, Any] | None = None,
        *,
        source_factory: Any = None,
    ) -> None:
        super().__init__()
        self.setWindowTitle("qrfield — bench")
        self.store = store
        self.app_settings: RunSettings = dataclasses.replace(
            store.group("run", RunSettings), **{k: v for k, v in (overrides or {}).items() if v is not None}
        )
        self.view_settings: ViewSettings = store.group("view", ViewSettings)
        classes = settings_classes()
        detector_cls = detector_settings_class()
        self.camera_model: CameraModel | None = None

        # ----- widgets
        self.preview = PreviewView()
        self.plots = PosePlots(self.view_settings.plot_window_s)
        self.pose_panel = PosePanel()
        self.banner = QtWidgets.QLabel("")
        self.banner.setObjectName("banner")
        self.banner.setWordWrap(True)
        self.banner.setStyleSheet("background: #a01818; color: white; padding: 6px; font-weight: bold;")
        self.banner_button = QtWidgets.QPushButton("Reopen source")
        banner_row = QtWidgets.QWidget()
        banner_layout = QtWidgets.QHBoxLayout(banner_row)
        banner_layout.setContentsMargins(0, 0, 0, 0)
        banner_layout.addWidget(self.banner, 1)
        banner_layout.addWidget(self.banner_button)
        self.banner_row = banner_row
        banner_row.hide()

        self.source_controls = SourceControls(store.group("picamera", Picamera2Settings))
        self.solver_controls = SolverControls(
            classes,
            {n: store.group(n, c) for n, c in classes.items()},
            detector=(detector_cls, store.group("detector", detector_cls)),
        )
        self.camera_controls = CameraControls()
        self.virtual_form = SettingsForm(VirtualBenchSettings, store.group("virtual", VirtualBenchSettings))
        show_app_settings(self.app_settings, self.source_controls, self.solver_controls, self.camera_controls)
        show_view_settings(self.view_settings, self.camera_controls)

        tabs = QtWidgets.QTabWidget()
        tabs.addTab(_scrolled(self.source_controls), "Source")
        tabs.addTab(_scrolled(self.solver_controls), "Detect && solve")
        tabs.addTab(self.camera_controls, "Camera")
        tabs.addTab(_scrolled(self.virtual_form), "Virtual bench")
        self.serial_panel = SerialPanel(store.group("serial", SerialLinkSettings))
        self.calibration_dialog: CalibrationDialog | None = None
        self.calibrate_button = QtWidgets.QPushButton("Calibrate camera…")
        self.calibrate_button.setObjectName("calibrate")
        self.camera_controls.layout().addRow(self.calibrate_button)
        self.calibrate_button.clicked.connect(self.open_calibration)
        tabs.addTab(_scrolled(self.serial_panel), "Serial")
        self.session_panel = SessionPanel(store, self._session_context)
        self.analysis_tab = AnalysisTab(self.session_panel.root)
        self.session_panel.set_default_solver(self.methods())
        self.session_panel.sessionChanged.connect(lambda s: self.analysis_tab.set_current(s and s.path))
        # The pose panel judges against the open session's criteria, else those of the New form.
        self.session_panel.sessionChanged.connect(lambda _s: self._show_criteria())
        self.session_panel.criteria_form.changed.connect(lambda *_: self._show_criteria())
        self._show_criteria()
        self.tabs = tabs
        # Under the preview, the wide pane: the live plots and the pages whose tables and pictures
        # need the width (rows, analysis, coverage); the controls keep the narrow right-hand tabs.
        work = QtWidgets.QTabWidget()
        work.setObjectName("work_tabs")
        work.addTab(self.plots, "Live plots")
        work.addTab(_scrolled(self.session_panel), "Session")
        work.addTab(_scrolled(self.analysis_tab), "Analysis")
        app = self.app_settings
        self.simulation_tab = SimulationTab(app.camera, app.side_mm, store.value(SIMULATION_KEY))
        work.addTab(self.simulation_tab, "Simulation")
        self.work_tabs = work

        left = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        top = QtWidgets.QWidget()
        top_layout = QtWidgets.QVBoxLayout(top)
        top_layout.setContentsMargins(0, 0, 0, 0)
        top_layout.addWidget(banner_row)
        top_layout.addWidget(self.preview, 1)
        left.addWidget(top)
        left.addWidget(work)
        left.setSizes([470, 330])
        self.left_splitter = left
        work.currentChanged.connect(self._work_tab_chosen)
        right = QtWidgets.QWidget()
        right_layout = QtWidgets.QVBoxLayout(right)
        right_layout.addWidget(self.pose_panel)
        right_layout.addWidget(tabs, 1)
        splitter = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        splitter.addWidget(left)
        splitter.addWidget(right)
        splitter.setSizes([820, 480])
        splitter.setStretchFactor(0, 3)
        splitter.setStretchFactor(1, 2)
        self.setCentralWidget(splitter)
        self.status_source = QtWidgets.QLabel("")
        self.status_rate = QtWidgets.QLabel("")
        self.statusBar().addWidget(self.status_source, 1)
        self.statusBar().addPermanentWidget(self.status_rate)
        self.resize(1300, 820)
        geometry = store.value("window")
        if isinstance(geometry, str):
            self.restoreGeometry(QtCore.QByteArray.fromBase64(geometry.encode()))

        # ----- worker
        config = self._run_config()
        self.worker = PipelineWorker(config, source_factory=source_factory)
        self.worker.sourceOpened.connect(self._on_source_opened)
        self.worker.sourceFailed.connect(self._on_source_failed)
        self.worker.sourceNote.connect(self._on_note)
        self.worker.result_sinks = (self.serial_panel.publisher,)  # every result, on the worker thread
        self.thread = start_worker(self.worker)
        self._closed = False

        # ----- wiring
        self.source_controls.openRequested.connect(self._open_source)
        self.source_controls.changed.connect(self._apply)
        self.solver_controls.changed.connect(self._apply)
        self.camera_controls.changed.connect(self._apply)
        self.virtual_form.changed.connect(self._apply)
        self.banner_button.clicked.connect(self._open_source)
        for problem in [*store.problems, *self.simulation_tab.problems]:
            self._on_note(problem)

        self.last: Processed | None = None
        self.frames_shown = 0
        self._t0 = time.monotonic()
        self._last_plot = 0.0
        self._rate_t = time.monotonic()
        self._rate_counts = (0, 0)
        self._rates = (0.0, 0.0)
        self.timer = QtCore.QTimer(self)
        self.timer.timeout.connect(self._redraw)
        self.timer.start(REDRAW_MS)

    # ---------------------------------------------------------------- configuration
    def methods(self) -> tuple[str, ...]:
        return methods_from_choice(self.app_settings.method)

    def _run_config(self) -> RunConfig:
        app = self.app_settings
        try:
            self.camera_model = resolve_camera(app.camera)
            self.camera_controls.camera_info.setText(
                f"{self.camera_model.width}x{self.camera_model.height} px, fx {self.camera_model.fx:.1f}, "
                f"fy {self.camera_model.fy:.1f}, cx {self.camera_model.cx:.1f}, cy {self.camera_model.cy:.1f}"
            )
        except CameraModelError as exc:
            self._on_note(f"camera model: {exc}")
            self.camera_controls.camera_info.setText(f"⚠ {exc}")
            if self.camera_model is None:
                self.camera_model = resolve_camera(DEFAULT_CAMERA)
        return RunConfig(
            source=app.source,
            camera=self.camera_model,
            side_mm=app.side_mm,
            methods=self.methods(),
            solver_settings=self.solver_controls.settings(),
            detector_settings=self.solver_controls.detector.value(),
            virtual=self.virtual_form.value(),
            loop=app.loop,
            picamera=self.source_controls.picamera.value(),
            pace=True,  # the preview plays a video at its own rate
            retry_s=app.retry_s,
        )

    def _apply(self, *_: object) -> None:
        """Controls changed: new settings for the worker, plots and panel."""
        self._reconfigure(reopen=False)

    def _reconfigure(self, reopen: bool) -> None:
        """New settings for the worker (``reopen``: and open the source again), plots and panel."""
        self.app_settings = app_settings_from(
            self.app_settings, self.source_controls, self.solver_controls, self.camera_controls
        )
        self.view_settings = view_settings_from(self.camera_controls)
        self.plots.set_window(self.view_settings.plot_window_s)
        self.simulation_tab.set_app_camera(self.app_settings.camera, self.app_settings.side_mm)
        self.worker.configure(self._run_config(), reopen=reopen)
        self.session_panel.refresh_state()

    def _show_criteria(self) -> None:
        session = self.session_panel.session
        criteria = session.info.criteria if session is not None else self.session_panel.criteria_form.value()
        self.pose_panel.set_criteria(criteria)

    def _work_tab_chosen(self, index: int) -> None:
        """A form or table page under the preview gets at least about half the height (never shrunk)."""
        if index <= 0:
            return
        top, bottom = self.left_splitter.sizes()
        if bottom < 0.5 * (top + bottom):
            half = (top + bottom) // 2
            self.left_splitter.setSizes([top + bottom - half - 40, half + 40])

    def _open_source(self) -> None:
        """Open the chosen source (again), e.g. after a failure."""
        self._reconfigure(reopen=True)
        self.banner_row.hide()

    def set_source(self, spec: str) -> None:
        """Switch to another source (as choosing it in the Source tab does)."""
        self.source_controls.set_source(spec)
        self._open_source()

    def set_method(self, choice: str) -> None:
        """Switch method: numerical, ippe or both (as the Solver tab does)."""
        self.solver_controls.method.setCurrentText(choice)

    def open_calibration(self) -> CalibrationDialog:
        """Show the calibration dialog (made once; it previews the frames this window draws)."""
        if self.calibration_dialog is None:
            settings = self.store.group("calibration", CalibrationDialogSettings)
            self.calibration_dialog = CalibrationDialog(self.stream_camera, settings, self)
            self.frameDrawn.connect(self.calibration_dialog.on_frame)
            self.calibration_dialog.cameraChosen.connect(self.use_camera)
        self.calibration_dialog.show()
        self.calibration_dialog.raise_()
        return self.calibration_dialog

    def use_camera(self, spec: str) -> None:
        """Make ``spec`` (preset or JSON path) the camera model, as choosing it in the Camera tab does."""
        with QtCore.QSignalBlocker(self.camera_controls.camera):
            self.camera_controls.camera.setCurrentText(spec)
        self._apply()

    def _session_context(self) -> BenchContext:
        """What a new session records and each row is checked against (the Session tab)."""
        return BenchContext(
            self.stream_camera(), self.app_settings.side_mm, self.methods(), self.solver_controls.settings()
        )

    def stream_camera(self) -> CameraModel:
        """The camera model the frames are measured with: the open stream's (a picamera2 stream's,
        derived through its sensor mode and crop; sessions record it), else the one named."""
        assert self.camera_model is not None
        return self.worker.source_camera or self.camera_model

    # ---------------------------------------------------------------- worker signals
    def _on_source_opened(self, description: str) -> None:
        self.camera_controls.report.show_stream(self.worker.stream_report)
        self.banner_row.hide()
        self.status_source.setText(f"source: {description}")
        self.plots.clear_history()

    def _on_source_failed(self, message: str) -> None:
        last = self.worker.latest.take()  # the worker stored it before failing: draw it, then mark it old
        if last is not None:
            self._draw(last)
        self.banner.setText(f"{message} — choose a source or press Reopen")
        self.banner_row.show()
        self.status_source.setText(f"source closed: {message}")
        self.pose_panel.mark_stale("no source: the values shown are the last ones measured")

    def _on_note(self, message: str) -> None:
        self.statusBar().showMessage(message, 8000)

    # ---------------------------------------------------------------- drawing
    def _redraw(self) -> None:
        item: Processed | None = self.worker.latest.take()
        now = time.monotonic()
        if item is not None:
            self._draw(item)
        self.serial_panel.refresh()
        if now - self._last_plot >= PLOT_PERIOD_S:
            self._last_plot = now
            self.plots.redraw(now - self._t0)
        if now - self._rate_t >= 1.0:
            processed, shown = self.worker.frames_processed, self.frames_shown
            dt = now - self._rate_t
            self._rates = ((processed - self._rate_counts[0]) / dt, (shown - self._rate_counts[1]) / dt)
            self._rate_counts, self._rate_t = (processed, shown), now
            self.status_rate.setText(
                f"processed {self._rates[0]:.1f} fps, shown {self._rates[1]:.1f} fps, "
                f"dropped {self.worker.latest.dropped}"
            )

    def _draw(self, item: Processed) -> None:
        self.last = item
        self.frames_shown += 1
        frame, result = item.frame, item.result
        methods = tuple(result.poses) or self.methods()
        self.preview.show_frame(frame.image)
        self.frameDrawn.emit(frame.image)
        self.preview.show_corners(None if result.detection is None else result.detection.corners_px)
        camera = result.camera or self.camera_model
        for k in range(2):
            pose = result.poses.get(methods[k]) if k < len(methods) else None
            drawable = pose is not None and pose.converged and np.all(np.isfinite(pose.rotation))
            self.preview.show_axes(
                k,
                pose.rotation if drawable else None,
                None if pose is None else pose.position_mm,
                result_side(self),
                camera,
            )
        self.preview.show_info(
            f"{result.status}  {self._rates[0]:.1f} fps  latency {result.latency_ms:.0f} ms  "
            f"(detect {result.detect_ms:.0f}, solve {result.solve_ms:.1f})  #{result.index}"
            + (f"  {item.frames_behind} behind" if item.frames_behind else "")
        )
        self.pose_panel.show_result(result, self.methods())
        t = item.frame.t_capture - self._t0
        for name in self.methods():
            pose = result.poses.get(name)
            values = None if pose is None else np.concatenate([pose.position_mm, pose.angles_deg])
            self.plots.add(name, t, values)
        if result.truth is not None:
            self.plots.add("true", t, np.concatenate([result.truth.position_mm, result.truth.angles_deg]))
        self.session_panel.on_processed(item)

    # ---------------------------------------------------------------- shutdown
    def save_settings(self) -> None:
        self.store.set_group("run", self.app_settings)
        self.store.set_group("view", self.view_settings)
        self.store.set_group("virtual", self.virtual_form.value())
        self.store.set_group("picamera", self.source_controls.picamera.value())
        for name, value in self.solver_controls.settings().items():
            self.store.set_group(name, value)
        self.store.set_group("detector", self.solver_controls.detector.value())
        self.store.set_group("serial", self.serial_panel.saved_settings())
        if self.calibration_dialog is not None:
            self.store.set_group("calibration", self.calibration_dialog.settings())
        self.session_panel.save_settings(self.store)
        self.store.set_value(SIMULATION_KEY, self.simulation_tab.settings())
        self.store.set_value("window", bytes(self.saveGeometry().toBase64()).decode())
        try:
            self.store.save()
        except OSError as exc:
            self._on_note(f"settings not saved: {exc}")

    def shutdown(self) -> None:
        """Save settings, stop the worker (it closes the source) and join its thread. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self.timer.stop()
        self.save_settings()
        self.simulation_tab.shutdown()
        stop_worker(self.worker, self.thread)
        self.serial_panel.shutdown()
        if self.calibration_dialog is not None:
            self.calibration_dialog.shutdown()
        self.session_panel.shutdown()
        self.analysis_tab.shutdown()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:
        if not self._closed and not self.session_panel.confirm_close():
            event.ignore()  # rows not written yet: the operator chose to keep the app open
            return
        self.shutdown()
        super().closeEvent(event)


def result_side(window: MainWindow) -> float:
    """Length of the drawn pose axes: one QR side, mm."""
    return window.app_settings.side_mm


def _scrolled(widget: QtWidgets.QWidget) -> QtWidgets.QScrollArea:
    area = QtWidgets.QScrollArea()
    area.setWidget(widget)
    area.setWidgetResizable(True)
    return area
