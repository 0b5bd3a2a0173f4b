"""The bench app's main window: on the left the preview over the pose panel, on the right the
tabs (Session first, Live plots, Analysis, Simulation, and Setup with the Source, Detect & solve,
Camera, Virtual bench and Serial pages). It fits an 800x480 touch display, 1024x600 and a desktop:
the window never grows beyond the screen, the pose panel's type shrinks on a small screen, and
only lists, tables and long settings forms scroll (docs/app.md).

The window never touches the camera: a :class:`~ui.worker.PipelineWorker` on its own QThread
captures and processes; the window takes the newest result on a QTimer (older unread results are
dropped, never queued) and redraws. Every change of a control becomes a new worker configuration
and is saved to the config file when the window closes.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.camera import DEFAULT_CAMERA, CameraModel, CameraModelError, resolve_camera
from qrfield.handeye import HandEyeSettings
from qrfield.methods import methods_from_choice
from qrfield.runconfig import ConfigStore, RunConfig, RunSettings
from qrfield.serial.link import SerialLinkSettings
from qrfield.solvers import settings_classes
from qrfield.sources import Picamera2Settings, VirtualBenchSettings
from qrfield.stream import StreamSettings
from ui import gui_gc
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
from ui.pose_panel import PosePanel, simulated_source_name
from ui.preview import PreviewPane, PreviewView
from ui.serial_panel import SerialPanel
from ui.sessions_panel import BenchContext, SessionPanel
from ui.settings_form import SettingsForm
from ui.simulation_tab import CONFIG_KEY as SIMULATION_KEY
from ui.simulation_tab import SimulationTab
from ui.touch import install_touch_style, touch_button
from ui.wheel_guard import install_wheel_guard
from ui.worker import STOP_WAIT_MS, PipelineWorker, Processed, start_worker, stop_worker

#: Redraw period of the GUI timer, ms (40 Hz, above the usual camera rate); plots redraw at most
#: every PLOT_PERIOD_S seconds.
REDRAW_MS = 25
PLOT_PERIOD_S = 0.2
#: The window's size on a desktop (px); never more than the screen's free area.
DESKTOP_SIZE = (1300, 820)
#: The smallest window (px): the Raspberry Pi Touch Display, the smallest size the layout is tested at.
MINIMUM_SIZE = (800, 480)
#: Config key of the screen's free area (px) the saved window geometry belongs to.
SCREEN_KEY = "window_screen"
#: Below this window height (px) the pose panel uses its compact type (800x480, 1024x600).
COMPACT_BELOW_PX = 700
#: The left column's (preview and pose) share of the window's width.
LEFT_SHARE = 0.44
#: The keys of the frequent actions: name -> (key sequence, what it does); their buttons' and the
#: tabs' tooltips name them (docs/app.md, "Keys").
SHORTCUTS = {
    "log_row": ("Ctrl+L", "log a row (the target's, with a plan)"),
    "cancel_row": ("Esc", "stop collecting the row (nothing logged)"),
    "undo_row": ("Ctrl+Z", "withdraw the last row (asks first)"),
    "new_session": ("Ctrl+N", "start a new session"),
    "resume": ("Ctrl+O", "resume a session"),
    "export_rows": ("Ctrl+E", "export the rows in force"),
    "next_tab": ("Ctrl+Tab", "the next tab"),
    "previous_tab": ("Ctrl+Shift+Tab", "the previous tab"),
    "full_screen": ("F11", "full screen and back"),
}
#: How many notes the window keeps (the status bar's tooltip shows the last few).
NOTES_KEPT = 50


def detector_settings_class() -> type:
    from qrfield.detect import DetectorSettings

    return DetectorSettings


class MainWindow(QtWidgets.QMainWindow):
    """The bench app. ``overrides`` (from the command line) replace saved RunSettings fields."""

    #: How long :meth:`shutdown` waits for the worker thread to end, ms.
    WORKER_STOP_MS = STOP_WAIT_MS

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
        install_wheel_guard()  # before any control is polished (see ui/wheel_guard.py)
        install_touch_style()  # every touch target 44 px high (ui/touch.py)
        gui_gc.hold(self)  # garbage with Qt objects is never collected on the worker (ui/gui_gc.py)
        self.setWindowTitle("qrfield — bench")
        self.store = store
        stored: RunSettings = store.group("run", RunSettings)
        self.app_settings: RunSettings = dataclasses.replace(
            stored, **{k: v for k, v in (overrides or {}).items() if v is not None}
        )
        #: What app.json gets for the source and the camera: the last ones that worked (a source
        #: that opened, a camera model that was found), else what it held; a source that failed to
        #: open never becomes the default that `qrfield run` then fails on.
        self.worked = {"source": stored.source, "camera": stored.camera}
        self._source_requests: dict[int, str] = {0: self.app_settings.source}  # request -> source
        self.view_settings: ViewSettings = store.group("view", ViewSettings)
        self.camera_model: CameraModel | None = None
        self.notes: list[str] = []  # every status note, in full (the status bar may shorten them)
        self._build_live_view()
        self._build_setup_tabs()
        self._build_work_tabs()
        self._build_layout()
        self._start_worker(source_factory)
        self._wire()
        self._start_redraw()
        self.session_panel.offer_reopen()

    # ---------------------------------------------------------------- builders
    def _build_live_view(self) -> None:
        """The preview (or its empty state), the source-failure banner and the pose panel."""
        self.preview = PreviewView()
        self.preview_pane = PreviewPane(self.preview)
        self.preview_pane.show_empty(f"Opening the source “{self.app_settings.source}” …")
        self.pose_panel = PosePanel()
        self.banner = QtWidgets.QLabel("")
        self.banner.setObjectName("banner")
        self.banner.setWordWrap(True)
        self.banner.setStyleSheet("color: white; font-weight: bold;")
        self.banner_button = touch_button("Reopen source", "reopen_source")
        banner_row = QtWidgets.QFrame()
        banner_row.setObjectName("banner_row")
        banner_row.setStyleSheet("QFrame#banner_row { background: #a01818; }")
        banner_layout = QtWidgets.QHBoxLayout(banner_row)
        banner_layout.setContentsMargins(6, 2, 6, 2)
        banner_layout.addWidget(self.banner, 1)
        banner_layout.addWidget(self.banner_button)
        self.banner_row = banner_row
        banner_row.hide()

    def _build_setup_tabs(self) -> None:
        """Source, detection and solvers, camera, virtual bench, serial: the Setup tab's pages."""
        store = self.store
        classes = settings_classes()
        detector_cls = detector_settings_class()
        self.source_controls = SourceControls(store.group("picamera", Picamera2Settings))
        self.solver_controls = SolverControls(
            classes,
            {n: store.group(n, c) for n, c in classes.items()},
            detector=(detector_cls, store.group("detector", detector_cls)),
            stream=(StreamSettings, store.group("stream", StreamSettings)),
        )
        self.camera_controls = CameraControls()
        self.virtual_form = SettingsForm(VirtualBenchSettings, store.group("virtual", VirtualBenchSettings))
        show_app_settings(self.app_settings, self.source_controls, self.solver_controls, self.camera_controls)
        show_view_settings(self.view_settings, self.camera_controls)
        self.serial_panel = SerialPanel(
            store.group("serial", SerialLinkSettings),
            handeye=store.group("handeye", HandEyeSettings),
            config_dir=store.path.parent,
        )
        self.calibration_dialog: CalibrationDialog | None = None
        self.calibrate_button = QtWidgets.QPushButton("Calibrate camera…")
        self.calibrate_button.setObjectName("calibrate")
        self.camera_controls.layout().addRow(self.calibrate_button)
        self.calibrate_button.clicked.connect(self.open_calibration)
        tabs = QtWidgets.QTabWidget()
        tabs.setObjectName("setup_tabs")
        tabs.addTab(_scrolled(self.source_controls), "Source")
        tabs.addTab(_scrolled(self.solver_controls), "Detect && solve")
        tabs.addTab(_scrolled(self.camera_controls), "Camera")
        tabs.addTab(_scrolled(self.virtual_form), "Virtual bench")
        tabs.addTab(_scrolled(self.serial_panel), "Serial")
        self.tabs = tabs

    def _build_work_tabs(self) -> None:
        """The right-hand tabs: Session first (what an operator does), then the plots, the
        analysis, the simulation and the Setup pages."""
        store, app = self.store, self.app_settings
        self.plots = PosePlots(self.view_settings.plot_window_s)
        self.session_panel = SessionPanel(store, self._session_context)
        self.analysis_tab = AnalysisTab(self.session_panel.root)
        self.session_panel.set_default_solver(self.methods())
        self.simulation_tab = SimulationTab(
            self._camera_that_works(), app.side_mm, store.value(SIMULATION_KEY)
        )
        work = QtWidgets.QTabWidget()
        work.setObjectName("work_tabs")
        work.addTab(self.session_panel, "Session")
        work.addTab(self.plots, "Live plots")
        work.addTab(self.analysis_tab, "Analysis")
        work.addTab(self.simulation_tab, "Simulation")
        work.addTab(self.tabs, "Setup")
        self.work_tabs = work

    def _build_layout(self) -> None:
        """Left: the picture over the pose; right: the tabs. Sized to fit the screen."""
        left = QtWidgets.QWidget()
        left_layout = QtWidgets.QVBoxLayout(left)
        left_layout.setContentsMargins(0, 0, 0, 0)
        left_layout.setSpacing(2)
        left_layout.addWidget(self.preview_pane, 1)
        left_layout.addWidget(self.pose_panel)
        splitter = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        splitter.setObjectName("main_splitter")
        splitter.setChildrenCollapsible(False)
        splitter.addWidget(left)
        splitter.addWidget(self.work_tabs)
        splitter.setStretchFactor(0, 2)
        splitter.setStretchFactor(1, 3)
        self.splitter = splitter
        central = QtWidgets.QWidget()
        central_layout = QtWidgets.QVBoxLayout(central)
        central_layout.setContentsMargins(0, 0, 0, 0)
        central_layout.setSpacing(0)
        central_layout.addWidget(self.banner_row)  # across the whole window: few lines, even at 800 px
        central_layout.addWidget(splitter, 1)
        self.setCentralWidget(central)
        # The window keeps the size it is given (the screen's): word-wrapped labels would otherwise
        # raise its minimum height to their height at the narrowest width and grow it past an
        # 800x480 screen. That everything fits is checked by tests/ui/test_app_layout.py.
        self.layout().setSizeConstraint(QtWidgets.QLayout.SizeConstraint.SetNoConstraint)
        self._build_status_bar()
        self._build_shortcuts()
        self._restore_geometry()

    def _build_shortcuts(self) -> None:
        """The keys of the frequent actions (:data:`SHORTCUTS`), for the whole window, each named in
        its button's (or tab's) tooltip."""
        panel = self.session_panel
        tabs = self.work_tabs
        actions = {
            "log_row": panel.log_row,
            "cancel_row": panel.cancel_row,
            "undo_row": panel.undo_row,
            "new_session": panel.show_new_dialog,
            "resume": panel.show_resume_dialog,
            "export_rows": panel.export_rows,
            "next_tab": lambda: tabs.setCurrentIndex((tabs.currentIndex() + 1) % tabs.count()),
            "previous_tab": lambda: tabs.setCurrentIndex((tabs.currentIndex() - 1) % tabs.count()),
            "full_screen": self.toggle_full_screen,
        }
        self.shortcuts: dict[str, QtGui.QShortcut] = {}
        for name, (keys, _what) in SHORTCUTS.items():
            shortcut = QtGui.QShortcut(QtGui.QKeySequence(keys), self)
            shortcut.setContext(QtCore.Qt.ShortcutContext.WindowShortcut)
            shortcut.activated.connect(actions[name])
            self.shortcuts[name] = shortcut
        buttons = {
            "log_row": panel.log_button,
            "cancel_row": panel.cancel_button,
            "undo_row": panel.undo_button,
            "new_session": panel.new_button,
            "resume": panel.resume_button,
            "export_rows": panel.export_button,
        }
        for name, button in buttons.items():
            keys, what = SHORTCUTS[name]
            shown = key_text(keys) + (" anywhere, Enter in the form" if name == "log_row" else "")
            button.setToolTip(f"{button.toolTip() or what} ({shown})")
        tip = (
            f"{key_text(SHORTCUTS['next_tab'][0])}: next tab, "
            f"{key_text(SHORTCUTS['previous_tab'][0])}: previous tab"
        )
        for k in range(tabs.count()):
            tabs.setTabToolTip(k, f"{tabs.tabText(k).replace('&&', '&')} ({tip})")

    def _build_status_bar(self) -> None:
        """The source on the left, the rates on the right; notes show between them for a while."""
        self.status_source = QtWidgets.QLabel("")
        self.status_source.setObjectName("status_source")
        self.status_rate = QtWidgets.QLabel("")
        self.status_rate.setObjectName("status_rate")
        self.statusBar().addWidget(self.status_source)
        self.statusBar().addPermanentWidget(self.status_rate)

    def _restore_geometry(self) -> None:
        """The size and place of the last session on the same screen size, else the desktop size;
        never beyond the screen. A screen of another size since (a 1024x600 display where the app
        ran at 800x480) gets the window fitted to it, not the old size."""
        geometry = self.store.value("window")
        saved_screen = self.store.value(SCREEN_KEY)
        free = self._free_area()
        same_screen = free is not None and saved_screen == [free.width(), free.height()]
        if isinstance(geometry, str) and same_screen:
            self.restoreGeometry(QtCore.QByteArray.fromBase64(geometry.encode()))
        elif free is not None:
            self.fit_new_screen(free)
        else:
            self.resize(*DESKTOP_SIZE)
        self.fit_screen()

    def _free_area(self) -> QtCore.QRect | None:
        screen = self.screen() or QtWidgets.QApplication.primaryScreen()
        return screen.availableGeometry() if screen is not None else None

    def fit_new_screen(self, free: QtCore.QRect) -> None:
        """A screen of another size (a new resolution, another monitor): the window takes the
        desktop size, or all of the screen's free area ``free`` when that is smaller."""
        if self.windowState() & (
            QtCore.Qt.WindowState.WindowFullScreen | QtCore.Qt.WindowState.WindowMaximized
        ):
            return  # the window system sizes it
        self.setMinimumSize(min(MINIMUM_SIZE[0], free.width()), min(MINIMUM_SIZE[1], free.height()))
        self.resize(min(DESKTOP_SIZE[0], free.width()), min(DESKTOP_SIZE[1], free.height()))

    def _watch_screen(self) -> None:
        """Follow the screen the window is on: its free area changing size refits the window."""
        handle = self.windowHandle()
        if handle is None or getattr(self, "_watched_handle", None) is handle:
            return
        self._watched_handle = handle
        handle.screenChanged.connect(self._screen_changed)
        self._screen_changed(handle.screen())

    def _screen_changed(self, screen: QtGui.QScreen | None) -> None:
        previous = getattr(self, "_watched_screen", None)
        if previous is not None and previous is not screen:
            previous.availableGeometryChanged.disconnect(self._free_area_changed)
            if screen is not None:
                self.fit_new_screen(screen.availableGeometry())
        self._watched_screen = screen
        if screen is not None and previous is not screen:
            screen.availableGeometryChanged.connect(self._free_area_changed)

    def _free_area_changed(self, free: QtCore.QRect) -> None:
        self.fit_new_screen(free)

    def _start_worker(self, source_factory: Any) -> None:
        config = self._run_config()
        self.serial_panel.set_context(config.side_mm, config.camera.name, config.source)
        self.worker = PipelineWorker(config, source_factory=source_factory)
        self.worker.sourceOpened.connect(self._on_source_opened)
        self.worker.sourceFailed.connect(self._on_source_failed)
        self.worker.sourceNote.connect(self._on_note)
        self.worker.sourceDown.connect(self._on_source_down)
        # Every result, on the worker thread: the serial link, the session's row recorder and the
        # guide of a planned experiment.
        panel = self.session_panel
        self.worker.result_sinks = (self.serial_panel.publisher, panel.recorder, panel.guide)
        self.thread = start_worker(self.worker)
        self._closed = False
        #: False when shutdown's bounded wait for the worker thread ran out (None before shutdown).
        self.worker_stopped: bool | None = None

    def _wire(self) -> None:
        self.source_controls.openRequested.connect(self._open_source)
        self.source_controls.changed.connect(self._apply)
        self.solver_controls.changed.connect(self._apply)
        self.camera_controls.changed.connect(self._apply)
        self.virtual_form.changed.connect(self._apply)
        self.banner_button.clicked.connect(self._open_source)
        self.session_panel.sessionChanged.connect(lambda s: self.analysis_tab.set_current(s and s.path))
        # The pose panel judges against the open session's criteria, else those of the New form.
        self.session_panel.sessionChanged.connect(lambda _s: self._show_criteria())
        self.session_panel.criteria_form.changed.connect(lambda *_: self._show_criteria())
        self._show_criteria()
        for problem in [*self.store.problems, *self.simulation_tab.problems]:
            self._on_note(problem)

    def _start_redraw(self) -> None:
        self.last: Processed | None = None
        self.frames_shown = 0
        self._frames_since_open = 0
        # The worker's request number of the operator's last "open this source": results of the
        # sources before it (Processed.generation lower) are never drawn.
        self._generation = 0
        self._t0 = time.monotonic()
        self._last_plot = 0.0
        self._rate_t = time.monotonic()
        self._rate_counts = (0, 0)
        self._rates = (0.0, 0.0)
        self.timer = QtCore.QTimer(self)
        self.timer.timeout.connect(self._redraw)
        self.timer.start(REDRAW_MS)

    # ---------------------------------------------------------------- size
    def fit_screen(self) -> None:
        """Never larger than the screen's free area (an 800x480 display gets all of itself)."""
        screen = self.screen() or QtWidgets.QApplication.primaryScreen()
        if screen is None:
            return
        free = screen.availableGeometry()
        # Never smaller than the smallest screen the layout is checked at (800x480).
        self.setMinimumSize(min(MINIMUM_SIZE[0], free.width()), min(MINIMUM_SIZE[1], free.height()))
        if self.width() > free.width() or self.height() > free.height():
            self.resize(min(self.width(), free.width()), min(self.height(), free.height()))

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:
        super().resizeEvent(event)
        compact = self.height() < COMPACT_BELOW_PX
        self.pose_panel.set_compact(compact)
        if not self.splitter.property("sized") or event.oldSize().width() != event.size().width():
            width = self.width()  # the splitter spans the window (its own width may lag behind)
            self.splitter.setSizes([round(width * LEFT_SHARE), width - round(width * LEFT_SHARE)])
            self.splitter.setProperty("sized", True)

    def toggle_full_screen(self) -> None:
        """F11: full screen (a Pi's touch display) and back."""
        self.setWindowState(self.windowState() ^ QtCore.Qt.WindowState.WindowFullScreen)

    # ---------------------------------------------------------------- configuration
    def methods(self) -> tuple[str, ...]:
        return methods_from_choice(self.app_settings.method)

    def _run_config(self) -> RunConfig:
        app = self.app_settings
        try:
            self.camera_model = resolve_camera(app.camera)
            self.worked["camera"] = app.camera
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
            stream=self.solver_controls.stream.value(),
        )

    def _camera_that_works(self) -> str:
        """The app's camera if its model is found, else the last one that was (saved with the study)."""
        try:
            resolve_camera(self.app_settings.camera)
        except CameraModelError:
            return self.worked["camera"]
        return self.app_settings.camera

    def _apply(self, *_: object) -> None:
        """Controls changed: new settings for the worker, plots and panel."""
        self._reconfigure(reopen=False)

    def _reconfigure(self, reopen: bool) -> int:
        """New settings for the worker (``reopen``: and open the source again), plots and panel;
        the worker's request number."""
        before = self._measuring()
        self.app_settings = app_settings_from(
            self.app_settings, self.source_controls, self.solver_controls, self.camera_controls
        )
        self.view_settings = view_settings_from(self.camera_controls)
        self.plots.set_window(self.view_settings.plot_window_s)
        config = self._run_config()
        self.simulation_tab.set_app_camera(self.worked["camera"], self.app_settings.side_mm)
        self.serial_panel.set_context(config.side_mm, config.camera.name, config.source)  # what HELLO reports
        request = self.worker.configure(config, reopen=reopen)
        self._source_requests[request] = config.source
        changed = ["the source"] if reopen else []
        after = self._measuring()
        changed += [what for what, value in before.items() if after.get(what) != value]
        if changed:  # a row being collected is not averaged across the change
            self.session_panel.measuring_changed(" and ".join(changed))
        self.session_panel.refresh_state()
        return request

    def _measuring(self) -> dict[str, Any]:
        """What a frame's measured pose depends on, by the name a message gives it: a change of
        any of them ends a row being collected (:meth:`SessionPanel.measuring_changed`). The
        virtual bench's pose is not among them: it is the card, which the operator may move."""
        app = self.app_settings
        return {
            "the camera model": app.camera,
            "the QR side": app.side_mm,
            "the solver": self.methods(),
            "the solver settings": self.solver_controls.settings(),
            "the detector settings": self.solver_controls.detector.value(),
            "the live stream settings": self.solver_controls.stream.value(),
        }

    def _show_criteria(self) -> None:
        session = self.session_panel.session
        criteria = session.info.criteria if session is not None else self.session_panel.criteria_form.value()
        self.pose_panel.set_criteria(criteria)

    def _open_source(self) -> None:
        """Open the chosen source (again), e.g. after a failure."""
        self.worker.latest.clear()  # a result of the source being replaced is not drawn any more
        self._frames_since_open = 0
        self.pose_panel.source_opened()  # its poses cannot be "stale" values of the new source
        self.preview_pane.show_empty(f"Opening the source “{self.source_controls.source()}” …")
        self._generation = self._reconfigure(reopen=True)
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
    def _source_that_opened(self) -> str | None:
        """The source of the worker's open source (by the request it was opened for), else None."""
        loop = self.worker.loop
        if loop.source is None:
            return None
        generation = loop.source_generation
        numbers = [n for n in self._source_requests if n <= generation]
        return self._source_requests[max(numbers)] if numbers else None

    def _on_source_opened(self, description: str) -> None:
        spec = self._source_that_opened()
        if spec is not None:
            self.worked["source"] = spec
            generation = self.worker.loop.source_generation
            newest = max(n for n in self._source_requests if n <= generation)
            self._source_requests = {n: v for n, v in self._source_requests.items() if n >= newest}
        self.camera_controls.report.show_stream(self.worker.stream_report)
        self.banner_row.hide()
        self.status_source.setText(f"source: {short_source(self.app_settings.source)}")
        self.status_source.setToolTip(description)
        self.source_controls.show_state(f"open: {description}")
        self.pose_panel.set_source_name(simulated_source_name(str(getattr(self.worker.source, "name", ""))))
        self.plots.clear_history()
        self.session_panel.source_opened()
        if self._frames_since_open == 0:
            self.preview_pane.show_empty(f"Waiting for the first frame from “{self.app_settings.source}” …")

    def _on_source_failed(self, message: str) -> None:
        last = self.worker.latest.take()  # the worker stored it before failing: draw it, then mark it old
        if last is not None and last.generation >= self._generation:  # of this source
            self._draw(last)
        self.banner.setText(message)  # what to do is on its button and in Setup › Source
        self.banner_row.show()
        self.status_source.setText(f"source: {short_source(self.app_settings.source)} (closed)")
        self.status_source.setToolTip(message)
        self.source_controls.show_state(f"closed: {message}", error=True)
        self.session_panel.source_lost(message)
        if self._frames_since_open == 0:  # nothing of this source to show: one clear empty state
            self.preview_pane.show_empty(  # why is in the banner above
                "No picture: the source is closed.\n\n"
                "Choose a source in Setup › Source, or press Reopen source."
            )
        self.pose_panel.show_source_down()  # why is in the banner

    def _on_source_down(self, reason: str) -> None:
        """No frames come (opening hangs, a camera stalls; also just before a failure): NOSRC, or
        STALE over the last real pose, in the pose panel."""
        self.pose_panel.show_source_down(reason)

    def _on_note(self, message: str) -> None:
        """A note from the worker or the settings: in the status bar for a while (shortened with
        "…" to the room there), in full in its tooltip and in :attr:`notes`."""
        self.notes = [*self.notes[-(NOTES_KEPT - 1) :], message]
        bar = self.statusBar()
        room = max(100, bar.width() - self.status_rate.width() - self.status_source.width() - 40)
        shown = bar.fontMetrics().elidedText(message, QtCore.Qt.TextElideMode.ElideRight, room)
        bar.showMessage(shown, 8000)
        bar.setToolTip("\n".join(self.notes[-5:]))

    # ---------------------------------------------------------------- drawing
    def _redraw(self) -> None:
        item: Processed | None = self.worker.latest.take()
        now = time.monotonic()
        if item is not None and item.generation < self._generation:
            item = None  # a frame of the source being replaced: not drawn (nor averaged into a row)
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
                f"{self._rates[0]:.1f} fps, shown {self._rates[1]:.1f}, dropped {self.worker.latest.dropped}"
            )
            self.status_rate.setToolTip("frames processed per second, drawn per second, dropped (not drawn)")

    def _draw(self, item: Processed) -> None:
        self.last = item
        self.frames_shown += 1
        self._frames_since_open += 1
        frame, result = item.frame, item.result
        methods = tuple(result.poses) or self.methods()
        self.preview_pane.show_live()
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
        status = result.reported_status(item.simulated)
        self.preview.show_info(
            f"{status}  {self._rates[0]:.1f} fps  latency {result.latency_ms:.0f} ms "
            f"(detect {result.detect_ms:.0f}, solve {result.solve_ms:.1f})  #{result.index}"
            + (f"  {item.frames_behind} behind" if item.frames_behind else "")
        )
        self.pose_panel.show_result(result, self.methods(), item.simulated)
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
        opened = self._source_that_opened()  # open now, its signal perhaps not handled yet
        if opened is not None:
            self.worked["source"] = opened
        self.store.set_group("run", dataclasses.replace(self.app_settings, **self.worked))
        self.store.set_group("view", self.view_settings)
        self.store.set_group("virtual", self.virtual_form.value())
        self.store.set_group("picamera", self.source_controls.picamera.value())
        for name, value in self.solver_controls.settings().items():
            self.store.set_group(name, value)
        self.store.set_group("detector", self.solver_controls.detector.value())
        self.store.set_group("stream", self.solver_controls.stream.value())
        self.store.set_group("serial", self.serial_panel.saved_settings())
        self.store.set_group("handeye", self.serial_panel.handeye_settings())
        if self.calibration_dialog is not None:
            self.store.set_group("calibration", self.calibration_dialog.settings())
        self.session_panel.save_settings(self.store)
        self.store.set_value(SIMULATION_KEY, self.simulation_tab.settings())
        self.store.set_value("window", bytes(self.saveGeometry().toBase64()).decode())
        free = self._free_area()
        if free is not None:
            self.store.set_value(SCREEN_KEY, [free.width(), free.height()])
        try:
            self.store.save()
        except OSError as exc:
            self._on_note(f"settings not saved: {exc}")

    def shutdown(self) -> None:
        """Save settings, stop the worker (it closes the source) and join its thread, then the
        background jobs; only after this may Qt delete the widgets (closeEvent). Idempotent."""
        if self._closed:
            return
        self._closed = True
        self.timer.stop()
        self.save_settings()
        self.simulation_tab.shutdown()
        self.worker_stopped = stop_worker(self.worker, self.thread, self.WORKER_STOP_MS)
        if self.worker_stopped:
            # Deleted with the window, on the GUI thread (the worker is back on it by now).
            self.worker.setParent(self)
            self.thread.setParent(self)
        else:
            # ui.worker keeps the worker and its thread alive until the thread ends.
            message = (
                f"the frame loop did not end within {self.WORKER_STOP_MS / 1000:g} s "
                f"(source {short_source(self.app_settings.source)!r} stuck in a read or close?); "
                "the window closes and the loop is left to end on its own"
            )
            self._on_note(message)
            print(f"qrfield: {message}", file=sys.stderr)
        self.serial_panel.shutdown()
        if self.calibration_dialog is not None:
            self.calibration_dialog.shutdown()
        self.session_panel.shutdown()
        self.analysis_tab.shutdown()
        self.camera_controls.report.shutdown()
        if self.worker_stopped:  # a loop left running keeps the collection on this thread
            gui_gc.release(self)

    def showEvent(self, event: QtGui.QShowEvent) -> None:
        super().showEvent(event)
        self.fit_screen()  # the screen is known for sure once shown
        self._watch_screen()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:
        if not self._closed and not self.session_panel.confirm_close():
            event.ignore()  # rows not written yet: the operator chose to keep the app open
            return
        self.shutdown()
        super().closeEvent(event)


def key_text(keys: str) -> str:
    """A key sequence as the platform writes it ("Ctrl+L")."""
    return QtGui.QKeySequence(keys).toString(QtGui.QKeySequence.SequenceFormat.NativeText)


def short_source(spec: str) -> str:
    """A source as the status bar names it: a file or folder by its name, others as given."""
    return Path(spec).name or spec if ("/" in spec or os.sep in spec) else spec


def result_side(window: MainWindow) -> float:
    """Length of the drawn pose axes: one QR side, mm."""
    return window.app_settings.side_mm


def _scrolled(widget: QtWidgets.QWidget) -> QtWidgets.QScrollArea:
    area = QtWidgets.QScrollArea()
    area.setWidget(widget)
    area.setWidgetResizable(True)
    return area
