"""The app's simulation tab: run a (small) simulation study in the background and show its results.

The study is the one of ``qrfield simulate`` (:mod:`qrfield.simulation`): every field is edited in
a form (the scalar fields' widgets come from :func:`qrfield.simulation.study.field_specs`; the
ranges and the solver list are text, read by the study's own parser) and validated by the study
itself, whose error is shown next to the field it names; Run is disabled while any field is bad.
The camera model and QR side follow the app's (editable when "use the app's camera" is off).

Run starts :func:`qrfield.simulation.run_study` as a :class:`ui.background.BackgroundJob` that
reports by Qt signal (progress, then the result); the GUI thread never computes (a large study
spreads over every core in worker processes; the small one runs in well under a second). Stop
cancels the job (the run's stop event): the grid points done are kept and shown as a partial
result. When a run started by Run ends, the job writes the study's output folder
(:func:`qrfield.simulation.write_outputs`: summary, samples, heatmap PNGs) into a new
``<YYYYmmdd-HHMMSS>`` folder under the output folder (default
:func:`qrfield.paths.simulations_dir`); "Open folder" opens it (or, with no file manager, says
where it is). With "re-run on change" ticked, once a study has been run, every change of a field
runs it again after a short pause (a run in progress is stopped and superseded): such a preview
is shown but not written. The tab shows the coverage table (per combination and solver, in both
readings: within criteria, and converged and within criteria; the mean, the seed's 77.28 %
beside it) and the heatmap of the largest solvable angle for a chosen combination and z, each on a
page of its own, with the run folder and Open folder under the pages: on an 800x480 screen every
button is in view and only the study's form and the table scroll, inside themselves.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.paths import simulations_dir
from qrfield.settings import SettingSpec
from qrfield.simulation import Progress, StudyConfig, StudyError, StudyResult, config_from_dict, run_study
from qrfield.simulation.outputs import (
    SEED_COVERAGE_PERCENT,
    heatmap_image,
    heatmap_name,
    new_run_folder,
    write_outputs,
)
from qrfield.simulation.study import SMALL_STUDY, field_specs, parse_override
from ui.background import BackgroundJob, JobControl
from ui.full_size import full_size_window
from ui.settings_form import set_widget_value, widget_for, widget_value
from ui.touch import FOLDER, TOUCH_PX, TouchCheckBox, ask_path, touch_button

RANGE_FIELDS = ("x_range", "y_range", "z_range")
#: Fields edited as text and read with the study's override parser.
TEXT_FIELDS = (*RANGE_FIELDS, "solvers")
#: The order of the form's rows.
FIELD_ORDER = (
    "camera",
    "side_mm",
    "x_range",
    "y_range",
    "z_range",
    "combinations",
    "sweep_limit_deg",
    "sweep_step_deg",
    "max_view_angle_deg",
    "degradation",
    "noise_px",
    "noise_seed",
    "solvers",
    "criteria.angle_deg",
    "criteria.position_mm",
    "criteria.n_max",
)
TEXT_LABELS = {
    "x_range": ("x range", "QR centre x in the camera frame: start, stop, step in mm (stop included)"),
    "y_range": ("y range", "QR centre y in the camera frame: start, stop, step in mm (stop included)"),
    "z_range": ("z range", "QR centre z (distance along the optical axis): start, stop, step in mm"),
    "solvers": (
        "solvers",
        "comma-separated: numerical, numerical-<guess> (e.g. numerical-parallelogram), ippe",
    ),
}
#: Section of the app's config file (qrfield.runconfig.ConfigStore) holding this tab's settings.
CONFIG_KEY = "simulation"
ERROR_STYLE = "color: #b00020;"
#: Pause after the last change before "re-run on change" starts the study (ms).
RERUN_DELAY_MS = 400
#: Platforms with no desktop to open a folder on.
HEADLESS_PLATFORMS = ("offscreen", "minimal", "vnc")


def range_text(values: Any) -> str:
    """[start, stop, step] as the form shows it: "200, 400, 100"."""
    if isinstance(values, (list, tuple)):
        return ", ".join(f"{float(v):g}" for v in values)
    return str(values)


def percent_text(value: float | None) -> str:
    return "n/a" if value is None else f"{100.0 * value:.2f} %"


def default_output_base() -> Path:
    """Where runs go when the output folder field is empty: the user's data folder."""
    return simulations_dir()


@dataclass
class RunOutcome:
    """What a finished (or stopped) run hands to the GUI thread (``out_dir`` None: a preview)."""

    result: StudyResult | None
    out_dir: Path | None
    paths: list[Path] = field(default_factory=list)
    error: str = ""
    superseded: bool = False


@dataclass
class StudyRun:
    """One run of the tab's study: what :func:`run_and_write` gets. ``superseded`` is set by the GUI
    thread when the form changed during the run: the run then writes nothing."""

    config: StudyConfig
    out_dir: Path | None
    superseded: bool = False


def run_and_write(control: JobControl, run: StudyRun) -> RunOutcome:
    """Run ``run``'s study (progress to ``control``, stopping when it is cancelled: the grid points
    done are kept, the result partial) and write its outputs into ``run.out_dir`` (none for a
    preview or a superseded run). Never raises: a failure is the outcome's ``error``."""
    try:
        result = run_study(run.config, progress=control.progress, stop=control.stop)
    except Exception as exc:  # report, never crash the app
        return RunOutcome(None, run.out_dir, error=f"{type(exc).__name__}: {exc}")
    outcome = RunOutcome(result, run.out_dir, superseded=run.superseded)
    if run.out_dir is not None and not run.superseded:
        try:
            outcome.paths = write_outputs(result, run.out_dir, command="qrfield app, simulation tab")
        except Exception as exc:
            outcome.error = f"outputs not written to {run.out_dir}: {type(exc).__name__}: {exc}"
    return outcome


class ImageView(QtWidgets.QWidget):
    """Shows a pixmap scaled to fit the widget, keeping its aspect ratio, centred (it takes the
    room its layout gives it; Full size… shows the picture at its own size)."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.pixmap = QtGui.QPixmap()
        size = QtWidgets.QSizePolicy.Policy
        self.setSizePolicy(size.Ignored, size.Ignored)
        self.setMinimumSize(120, 80)

    def set_pixmap(self, pixmap: QtGui.QPixmap) -> None:
        self.pixmap = pixmap
        self.update()

    def sizeHint(self) -> QtCore.QSize:
        return QtCore.QSize(400, 300)

    def paintEvent(self, _event: QtGui.QPaintEvent) -> None:
        if self.pixmap.isNull():
            return
        painter = QtGui.QPainter(self)
        painter.setRenderHint(QtGui.QPainter.RenderHint.SmoothPixmapTransform)
        scaled = self.pixmap.size().scaled(self.size(), QtCore.Qt.AspectRatioMode.KeepAspectRatio)
        corner = QtCore.QPoint((self.width() - scaled.width()) // 2, (self.height() - scaled.height()) // 2)
        painter.drawPixmap(QtCore.QRect(corner, scaled), self.pixmap)
        painter.end()


class SimulationTab(QtWidgets.QWidget):
    """The simulation tab. ``app_camera`` / ``app_side_mm``: the app's current camera model
    (NAME[@WxH] or PATH.json[@WxH]) and QR side (mm); see :meth:`set_app_camera`.

    Signals: ``progressed(Progress)``; ``finished(StudyResult | None)`` once a run has ended and
    its results are shown (None when it failed; the reason is in the status line).
    """

    progressed = QtCore.Signal(object)
    finished = QtCore.Signal(object)

    def __init__(
        self,
        app_camera: str,
        app_side_mm: float,
        saved: dict[str, Any] | None = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.app_camera = app_camera
        self.app_side_mm = float(app_side_mm)
        self.config: StudyConfig | None = None
        self.result: StudyResult | None = None
        self.outcome: RunOutcome | None = None
        self.run: StudyRun | None = None  # the run in progress
        self.problems: list[str] = []
        self.specs: dict[str, SettingSpec] = {spec.name: spec for spec in field_specs()}
        self.job = BackgroundJob("simulation study", self)
        self._has_run = False
        self._ready = False
        self._build_run_controls()
        self.pages = QtWidgets.QTabWidget()
        self.pages.addTab(self._build_study_page(), "Study")
        self.pages.addTab(self._build_coverage_page(), "Coverage")
        self.pages.addTab(self._build_heatmap_page(), "Heatmap")
        self._build_run_folder_row()
        self._build_layout()
        self._connect_signals()
        self.apply_preset(SMALL_STUDY)
        if saved:
            self.restore(saved)
        self._follow_toggled(self.follow_app.isChecked())
        self._ready = True

    # ---------------------------------------------------------------- builders
    def _build_study_page(self) -> QtWidgets.QWidget:
        """The presets and the output folder over the study form (one row per field, its error
        under it; the form scrolls inside itself on a small screen)."""
        self.small_button = QtWidgets.QPushButton("Small study")
        self.small_button.setToolTip("5 x 3 x 2 grid, 12 combinations, sweep 0..60 deg step 5: a few seconds")
        self.default_button = QtWidgets.QPushButton("Default study")
        self.default_button.setToolTip("the shipped study of qrfield simulate (study-default.toml)")
        presets = QtWidgets.QHBoxLayout()
        presets.addWidget(QtWidgets.QLabel("presets:"))
        presets.addWidget(self.small_button)
        presets.addWidget(self.default_button)
        presets.addStretch(1)
        form = QtWidgets.QFormLayout()
        form.setFieldGrowthPolicy(QtWidgets.QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.follow_app = TouchCheckBox("use the app's camera model and QR side")
        self.follow_app.setChecked(True)
        form.addRow(self.follow_app)
        self.widgets: dict[str, QtWidgets.QWidget] = {}
        self.errors: dict[str, QtWidgets.QLabel] = {}
        for name in FIELD_ORDER:
            self._add_field_row(form, name)
        self.general_error = _error_label("")
        form.addRow(self.general_error)
        fields = QtWidgets.QWidget()
        fields_layout = QtWidgets.QVBoxLayout(fields)
        fields_layout.addLayout(form)
        fields_layout.addStretch(1)
        output = QtWidgets.QHBoxLayout()
        output.addWidget(QtWidgets.QLabel("output folder"))
        output.addLayout(self._build_output_row(), 1)
        page = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(page)
        layout.addLayout(presets)
        layout.addLayout(output)
        layout.addWidget(_scrolled(fields), 1)  # the long form scrolls inside itself, no button in it
        return page

    def _add_field_row(self, form: QtWidgets.QFormLayout, name: str) -> None:
        """One study field: its widget (text for ranges and solvers, else from its SettingSpec)
        with its error label under it; every change validates the form."""
        if name in TEXT_FIELDS:
            label, tip = TEXT_LABELS[name]
            widget: QtWidgets.QWidget = QtWidgets.QLineEdit()
            widget.setToolTip(tip)
            widget.setObjectName(name)
            widget.textChanged.connect(self._validate)
        else:
            label = self.specs[name].label
            widget = widget_for(self.specs[name])
            for signal_name in ("toggled", "currentTextChanged", "valueChanged", "textChanged"):
                signal = getattr(widget, signal_name, None)
                if signal is not None:
                    signal.connect(self._validate)
                    break
        error = _error_label(f"error:{name}")
        cell = QtWidgets.QWidget()
        cell_layout = QtWidgets.QVBoxLayout(cell)
        cell_layout.setContentsMargins(0, 0, 0, 0)
        cell_layout.setSpacing(1)
        cell_layout.addWidget(widget)
        cell_layout.addWidget(error)
        row_label = QtWidgets.QLabel(label)
        row_label.setToolTip(widget.toolTip())
        form.addRow(row_label, cell)
        self.widgets[name] = widget
        self.errors[name] = error

    def _build_output_row(self) -> QtWidgets.QHBoxLayout:
        self.output_dir = QtWidgets.QLineEdit()
        self.output_dir.setPlaceholderText(f"(each run in a new folder under {default_output_base()})")
        self.output_dir.setToolTip(
            "each run started by Run writes its outputs into a new <YYYYmmdd-HHMMSS> folder inside this one"
        )
        browse = touch_button("…")
        browse.setFixedWidth(TOUCH_PX)
        browse.setObjectName("browse_output")
        browse.setToolTip("choose the output folder")
        browse.clicked.connect(self._browse_output)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.output_dir, 1)
        row.addWidget(browse)
        return row

    def _build_coverage_page(self) -> QtWidgets.QWidget:
        """The coverage table (it scrolls inside itself) under what its two readings mean."""
        self.table = QtWidgets.QTableWidget(0, 0)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.verticalHeader().setDefaultSectionSize(20)
        coverage_label = QtWidgets.QLabel(
            "Coverage: share of in-view samples meeting the criteria. <i>within</i>: the pose meets "
            "them and the solver stopped before n_max; <i>converged</i>: its own converged flag holds too"
        )
        coverage_label.setWordWrap(True)
        page = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(page)
        layout.addWidget(coverage_label)
        layout.addWidget(self.table, 1)
        return page

    def _build_heatmap_page(self) -> QtWidgets.QWidget:
        """The heatmap (scaled to the room there is) with its choice of combination and z, Full size."""
        self.combo_choice = QtWidgets.QComboBox()
        self.combo_choice.setObjectName("heatmap_combination")
        self.combo_choice.setSizeAdjustPolicy(
            QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon
        )
        self.combo_choice.setMinimumContentsLength(12)
        self.z_choice = QtWidgets.QComboBox()
        self.z_choice.setObjectName("heatmap_z")
        self.heatmap = ImageView()
        self.heatmap_path = _selectable_label("")
        self.full_size_button = touch_button("Full size…", "heatmap_full_size_button")
        self.full_size_button.setToolTip("the heatmap at its own size, in a window of its own")
        self.full_size_button.setEnabled(False)
        choose = QtWidgets.QHBoxLayout()
        choose.addWidget(QtWidgets.QLabel("combination"))
        choose.addWidget(self.combo_choice, 1)
        choose.addWidget(QtWidgets.QLabel("z"))
        choose.addWidget(self.z_choice)
        choose.addWidget(self.full_size_button)
        page = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(page)
        layout.addWidget(QtWidgets.QLabel("Largest solvable angle (deg) over the x-y grid"))
        layout.addLayout(choose)
        layout.addWidget(self.heatmap, 1)
        layout.addWidget(self.heatmap_path)
        return page

    def _build_run_folder_row(self) -> None:
        """The last run's folder and Open folder, under the pages (in view on every page)."""
        self.output_label = _selectable_label("no run yet")
        self.open_button = QtWidgets.QPushButton("Open folder")
        self.open_button.setToolTip("open the last saved run's folder in the file manager")
        self.open_button.setEnabled(False)
        self.run_folder_row = QtWidgets.QHBoxLayout()
        self.run_folder_row.addWidget(self.output_label, 1)
        self.run_folder_row.addWidget(self.open_button)

    def _build_run_controls(self) -> None:
        """Run, Stop, "re-run on change" (with its debounce timer), the progress bar and status lines."""
        self.run_button = QtWidgets.QPushButton("Run")
        self.run_button.setToolTip("run the study and save its outputs in a new folder")
        self.stop_button = QtWidgets.QPushButton("Stop")
        self.stop_button.setEnabled(False)
        self.auto_run = TouchCheckBox("re-run on change")
        self.auto_run.setChecked(True)
        self.auto_run.setToolTip(
            "once a study has been run, run it again shortly after each change of a field "
            "(shown, not saved: Run saves)"
        )
        self._rerun_timer = QtCore.QTimer(self)
        self._rerun_timer.setSingleShot(True)
        self._rerun_timer.setInterval(RERUN_DELAY_MS)
        self.progress = QtWidgets.QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setValue(0)
        self.progress.setFormat("%p %")
        self.size_label = QtWidgets.QLabel("")
        self.size_label.setWordWrap(True)
        self.status = QtWidgets.QLabel("")
        self.status.setWordWrap(True)

    def _build_layout(self) -> None:
        controls = QtWidgets.QHBoxLayout()
        controls.addWidget(self.run_button)
        controls.addWidget(self.stop_button)
        controls.addWidget(self.auto_run)
        controls.addWidget(self.progress, 1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(controls)
        layout.addWidget(self.status)
        layout.addWidget(self.size_label)
        layout.addWidget(self.pages, 1)
        layout.addLayout(self.run_folder_row)

    def _connect_signals(self) -> None:
        self.job.progressed.connect(self._on_progress)
        self.job.finished.connect(self._on_done)
        self.job.failed.connect(self._on_failed)
        self._rerun_timer.timeout.connect(self._rerun)
        self.run_button.clicked.connect(lambda: self.start(save=True))  # not clicked(checked)
        self.stop_button.clicked.connect(self.stop)
        self.small_button.clicked.connect(lambda: self.apply_preset(SMALL_STUDY))
        self.default_button.clicked.connect(lambda: self.apply_preset({}))
        self.follow_app.toggled.connect(self._follow_toggled)
        self.combo_choice.currentIndexChanged.connect(self._show_heatmap)
        self.z_choice.currentIndexChanged.connect(self._show_heatmap)
        self.open_button.clicked.connect(self._open_output)
        self.full_size_button.clicked.connect(self.show_full_size)

    # ---------------------------------------------------------------- the form
    def raw_study(self) -> dict[str, Any]:
        """The form as a study dict (the TOML's shape), ranges and solvers read by the study's parser."""
        raw: dict[str, Any] = {}
        criteria: dict[str, Any] = {}
        for name, widget in self.widgets.items():
            if name in TEXT_FIELDS:
                assert isinstance(widget, QtWidgets.QLineEdit)
                value = parse_override(f"{name}={widget.text()}")[name]
            else:
                value = widget_value(widget)
            if name.startswith("criteria."):
                criteria[name.partition(".")[2]] = value
            else:
                raw[name] = value
        raw["criteria"] = criteria
        return raw

    def form_texts(self) -> dict[str, Any]:
        """The form as saved in the config: widget values (range and solver fields as their text)."""
        return {
            name: (widget.text() if isinstance(widget, QtWidgets.QLineEdit) else widget_value(widget))
            for name, widget in self.widgets.items()
        }

    def show_study(self, config: StudyConfig, keep_camera: bool = True) -> None:
        """Fill the form from ``config`` (the camera and side stay as they are with ``keep_camera``)."""
        for name in self.widgets:
            if keep_camera and name in ("camera", "side_mm"):
                continue
            if name.startswith("criteria."):
                value: Any = getattr(config.criteria, name.partition(".")[2])
            else:
                value = getattr(config, name)
            self._set_field(name, value)
        self._validate()

    def apply_preset(self, fields: dict[str, Any]) -> None:
        """The shipped study with ``fields`` over it (SMALL_STUDY, or {} for the shipped default)."""
        self.show_study(config_from_dict(fields))

    def _set_field(self, name: str, value: Any) -> None:
        widget = self.widgets[name]
        blocker = QtCore.QSignalBlocker(widget)
        if name in RANGE_FIELDS:
            widget.setText(range_text(value))  # type: ignore[attr-defined]
        elif name == "solvers":
            widget.setText(", ".join(value) if isinstance(value, (list, tuple)) else str(value))  # type: ignore[attr-defined]
        else:
            set_widget_value(widget, self.specs[name], value)
        del blocker

    def set_app_camera(self, camera: str, side_mm: float) -> None:
        """The app's camera model and QR side changed; the form follows them unless unticked."""
        self.app_camera, self.app_side_mm = camera, float(side_mm)
        if self.follow_app.isChecked():
            self._set_field("camera", camera)
            self._set_field("side_mm", self.app_side_mm)
            self._validate()

    def _follow_toggled(self, follow: bool) -> None:
        for name in ("camera", "side_mm"):
            self.widgets[name].setEnabled(not follow)
        if follow:
            self.set_app_camera(self.app_camera, self.app_side_mm)

    def _validate(self, *_: object) -> None:
        """Check the form with the study's own validation; show its error next to the field it names."""
        for label in (*self.errors.values(), self.general_error):
            label.hide()
        try:
            self.config = config_from_dict(self.raw_study())
        except StudyError as exc:
            self.config = None
            message = str(exc).removeprefix("study: ")
            self._show_error(message)
            self.size_label.setText("")
        else:
            size = self.config.size()
            self.size_label.setText(
                f"Size: {self.config.describe_size()}"
                + (" (a large study: a few seconds on every core)" if size["poses"] > 20_000 else "")
            )
        self._update_buttons()
        self._schedule_rerun()

    # ---------------------------------------------------------------- re-run on change
    def _schedule_rerun(self) -> None:
        """After a change: run the study again shortly (debounced), once one has been run."""
        if not (self._ready and self._has_run and self.auto_run.isChecked()) or self.config is None:
            self._rerun_timer.stop()
            return
        shown = self.result
        if self.run is None and shown is not None and not shown.partial and shown.config == self.config:
            self._rerun_timer.stop()  # the study shown is the study in the form
            return
        self._rerun_timer.start()

    def _rerun(self) -> None:
        if self.config is None:
            return
        if self.run is not None:
            if self.run.config == self.config:
                return
            # Supersede the run in progress; _on_done starts the new one.
            self.run.superseded = True
            self.job.cancel()
            return
        self.start(save=False)

    def _show_error(self, message: str) -> None:
        match = re.search(r"field '([\w.\-]+)'", message)
        name = match[1] if match else ""
        if name.startswith("solver."):
            name = "solvers"
        label = self.errors.get(name, self.general_error)
        label.setText(message)
        label.show()

    def error_text(self, name: str) -> str:
        """The error shown next to field ``name`` ("" when none)."""
        label = self.errors[name]
        return label.text() if not label.isHidden() else ""

    def _update_buttons(self) -> None:
        running = self.run is not None
        self.run_button.setEnabled(self.config is not None and not running)
        self.stop_button.setEnabled(running)
        for button in (self.small_button, self.default_button):
            button.setEnabled(not running)

    def _browse_output(self) -> None:
        folder = ask_path(self, "Output folder", self.output_dir.text(), mode=FOLDER)
        if folder:
            self.output_dir.setText(folder)

    # ---------------------------------------------------------------- persistence
    def settings(self) -> dict[str, Any]:
        """The tab's settings for the app's config file (section ``simulation``)."""
        return {
            "study": self.form_texts(),
            "follow_app_camera": self.follow_app.isChecked(),
            "output_dir": self.output_dir.text(),
            "rerun_on_change": self.auto_run.isChecked(),
        }

    def restore(self, saved: dict[str, Any]) -> None:
        """Show saved settings; a value that cannot be shown is skipped and noted in ``problems``."""
        if not isinstance(saved, dict):
            self.problems.append(f"{CONFIG_KEY}: settings are not a table; defaults used")
            return
        study = saved.get("study", {})
        for name, value in (study if isinstance(study, dict) else {}).items():
            if name not in self.widgets:
                continue
            try:
                if name in TEXT_FIELDS and not isinstance(value, str):
                    raise TypeError(f"expected text, got {value!r}")
                self._set_field(name, value)
            except (TypeError, ValueError) as exc:
                self.problems.append(f"{CONFIG_KEY}: {name}: {exc}; default used")
        self.follow_app.setChecked(bool(saved.get("follow_app_camera", True)))
        self.auto_run.setChecked(bool(saved.get("rerun_on_change", True)))
        if isinstance(saved.get("output_dir"), str):
            self.output_dir.setText(saved["output_dir"])
        self._validate()

    # ---------------------------------------------------------------- running
    def output_folder(self) -> Path:
        """A new folder for one run's outputs: <YYYYmmdd-HHMMSS> under the output folder."""
        text = self.output_dir.text().strip()
        return new_run_folder(Path(text).expanduser() if text else default_output_base())

    def start(self, save: bool = True) -> None:
        """Run the form's study in the background: the Run button (``save``: write its outputs),
        or a re-run after a change (a preview, not written)."""
        if self.run is not None or self.config is None:
            return
        self._rerun_timer.stop()
        out_dir = None
        if save:
            try:
                out_dir = self.output_folder()
            except OSError as exc:
                self.status.setText(f"⚠ cannot create the output folder: {exc}")
                return
        run = StudyRun(self.config, out_dir)
        if not self.job.start_controlled(run_and_write, run):
            return  # the last run's thread is still ending; its outcome starts the next one
        self._has_run = True
        self.run = run
        self.progress.setValue(0)
        self.status.setText(f"running: {self.config.size()['poses']} poses …")
        self._update_buttons()

    def stop(self) -> None:
        """Ask the run to stop after the tasks in progress; what is done is kept (Stop button)."""
        if self.run is not None:
            self._rerun_timer.stop()
            self.run.superseded = False
            self.job.cancel()
            self.status.setText("stopping after the tasks in progress …")
            self.stop_button.setEnabled(False)

    def _on_progress(self, p: Progress) -> None:
        self.progress.setValue(round(1000 * p.fraction))
        self.status.setText(
            f"running: {p.done_poses} / {p.total_poses} poses, {p.poses_per_second:.0f} poses/s, "
            f"{p.seconds:.1f} s; combination {p.combination}"
        )
        self.progressed.emit(p)

    def _on_failed(self, message: str) -> None:
        """run_and_write never raises; should it, the run still ends with a message."""
        self._on_done(RunOutcome(None, self.run.out_dir if self.run else None, error=message))

    def _on_done(self, outcome: RunOutcome) -> None:
        self.run = None
        if outcome.superseded:  # a field changed during the run: run the new study instead
            self._update_buttons()
            self.status.setText("the study changed: running it again …")
            self._rerun()
            return
        if outcome.out_dir is not None or self.outcome is None:
            self.outcome = outcome
        self.result = outcome.result
        self._update_buttons()
        result = outcome.result
        if result is None:
            self.status.setText(f"⚠ the study failed: {outcome.error}")
            self.finished.emit(None)
            return
        total = result.done.size * result.sweep_deg.size
        rate = result.poses_done / result.seconds if result.seconds > 0 else 0.0
        if result.partial:
            text = (
                f"PARTIAL (stopped): {result.poses_done} of {total} poses in {result.seconds:.1f} s "
                f"({rate:.0f} poses/s); the figures cover the grid points done"
            )
        else:
            self.progress.setValue(1000)
            text = f"done: {result.poses_done} poses in {result.seconds:.1f} s ({rate:.0f} poses/s)"
        if outcome.out_dir is None:
            text += " — a preview after a change, not saved (Run saves it)"
        if outcome.error:
            text += f"\n⚠ {outcome.error}"
        self.status.setText(text)
        self.show_result(result, outcome.paths, outcome.out_dir)
        self.pages.setCurrentIndex(1)
        self.finished.emit(result)

    # ---------------------------------------------------------------- results
    def show_result(self, result: StudyResult, paths: list[Path], out_dir: Path | None) -> None:
        """Fill the coverage table (two readings per solver) and the heatmap choices."""
        self._fill_coverage_table(result)
        self._fill_heatmap_choices(result, paths)
        saved = self.outcome.out_dir if self.outcome is not None else None
        if out_dir is not None:
            self.output_label.setText(f"run folder: {out_dir}")
        elif saved is not None:
            self.output_label.setText(f"preview, not saved; the last saved run: {saved}")
        else:
            self.output_label.setText("preview, not saved (Run saves the study in a new folder)")
        self.open_button.setEnabled(saved is not None and saved.is_dir())
        self._show_heatmap()

    def _fill_coverage_table(self, result: StudyResult) -> None:
        """Per combination (and the mean), two readings per solver; the seed's mean beside them."""
        solvers = list(result.solvers)
        rows = [c.name for c in result.combinations] + ["mean"]
        readings = (("within criteria", False), ("converged + within", True))
        self.table.clear()
        self.table.setRowCount(len(rows))
        self.table.setColumnCount(2 * len(solvers) + 1)
        seed_header = "seed (Teoh 2022)"
        headers = [f"{key}\n{name}" for key in solvers for name, _ in readings]
        self.table.setHorizontalHeaderLabels([*headers, seed_header])
        self.table.setVerticalHeaderLabels(rows)
        bold = QtGui.QFont()
        bold.setBold(True)
        mean_row = len(rows) - 1
        for c, combo in enumerate(result.combinations):
            self.table.verticalHeaderItem(c).setToolTip(combo.describe())
        for s, key in enumerate(solvers):
            for r, (_, converged_only) in enumerate(readings):
                column = 2 * s + r
                for c in range(len(result.combinations)):
                    value = result.coverage(key, c, converged_only=converged_only)
                    self.table.setItem(c, column, _cell(percent_text(value)))
                item = _cell(percent_text(result.mean_coverage(key, converged_only=converged_only)))
                item.setFont(bold)
                self.table.setItem(mean_row, column, item)
        seed = _cell(f"{SEED_COVERAGE_PERCENT:.2f} %")
        seed.setToolTip("the thesis' mean coverage (MATLAB, numerical model), for comparison")
        seed.setFont(bold)
        self.table.setItem(mean_row, 2 * len(solvers), seed)
        self.table.resizeColumnsToContents()
        header_h = self.table.horizontalHeader().height()
        rows_h = sum(self.table.rowHeight(r) for r in range(len(rows)))
        self.table.setMinimumHeight(min(header_h + rows_h + 2 * self.table.frameWidth() + 18, 280))

    def _fill_heatmap_choices(self, result: StudyResult, paths: list[Path]) -> None:
        """The combinations with samples and the z values to choose from; the PNGs written for them."""
        written = {p.name: p for p in paths if p.parent.name == "heatmaps"}
        self._heatmaps: dict[tuple[int, int], Path] = {}
        for c, combo in enumerate(result.combinations):
            for iz, z in enumerate(result.z_mm):
                path = written.get(heatmap_name(combo.name, z))
                if path is not None:
                    self._heatmaps[(c, iz)] = path
        self._heatmap_cache: dict[tuple[int, int], QtGui.QPixmap] = {}
        blockers = [QtCore.QSignalBlocker(self.combo_choice), QtCore.QSignalBlocker(self.z_choice)]
        self.combo_choice.clear()
        for c, combo in enumerate(result.combinations):
            if result.done[c].any():
                self.combo_choice.addItem(f"{combo.name} ({combo.describe()})", c)
        self.z_choice.clear()
        for iz, z in enumerate(result.z_mm):
            self.z_choice.addItem(f"{z:g} mm", iz)
        del blockers

    def heatmap_shown(self) -> Path | None:
        """The PNG shown now (None when none)."""
        return getattr(self, "_shown_path", None)

    def _show_heatmap(self, *_: object) -> None:
        """Draw the chosen combination and z from the result (saved or not); name its PNG if written."""
        c, iz = self.combo_choice.currentData(), self.z_choice.currentData()
        result = self.result
        path = getattr(self, "_heatmaps", {}).get((c, iz))
        self._shown_path = path
        if result is None or c is None or iz is None or not result.done[c].any():
            self.heatmap.set_pixmap(QtGui.QPixmap())
            self.heatmap_path.setText("no heatmap for this choice")
            self.full_size_button.setEnabled(False)
            return
        cache = getattr(self, "_heatmap_cache", {})
        if (c, iz) not in cache:
            rgb = np.ascontiguousarray(heatmap_image(result, c, iz)[..., ::-1])  # BGR -> RGB
            height, width = rgb.shape[:2]
            image = QtGui.QImage(rgb.data, width, height, 3 * width, QtGui.QImage.Format.Format_RGB888)
            cache[(c, iz)] = QtGui.QPixmap.fromImage(image.copy())
            self._heatmap_cache = cache
        self.heatmap.set_pixmap(cache[(c, iz)])
        self.heatmap_path.setText(str(path) if path is not None else "(a preview: not saved)")
        self.full_size_button.setEnabled(True)

    def show_full_size(self) -> None:
        """The heatmap shown, at its own size in a scrollable window of its own."""
        if self.heatmap.pixmap.isNull():
            return
        full_size_window(self, self.heatmap.pixmap, self.heatmap_path.text(), "heatmap_full_size")

    def _open_output(self) -> bool:
        """Open the last saved run's folder in the desktop's file manager (Open folder button).

        Without a desktop (offscreen, a Pi with no monitor) or when nothing opens it, the status
        line says where the folder is instead. Returns whether a file manager was asked to open it.
        """
        folder = self.outcome.out_dir if self.outcome is not None else None
        if folder is None:
            return False
        platform = QtGui.QGuiApplication.platformName()
        opened = platform not in HEADLESS_PLATFORMS and QtGui.QDesktopServices.openUrl(
            QtCore.QUrl.fromLocalFile(str(folder))
        )
        if not opened:
            self.status.setText(f"no file manager to open it here; the run folder is {folder}")
        return opened

    def shutdown(self, timeout_s: float = 5.0) -> None:
        """Stop a running study and wait up to ``timeout_s`` for it (the app is closing)."""
        self.job.cancel()
        self.job.join(timeout_s)


def _cell(text: str) -> QtWidgets.QTableWidgetItem:
    item = QtWidgets.QTableWidgetItem(text)
    item.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
    return item


def _error_label(name: str) -> QtWidgets.QLabel:
    """A hidden, wrapped, red label for a field's (or the form's) error."""
    label = QtWidgets.QLabel("")
    label.setObjectName(name)
    label.setWordWrap(True)
    label.setStyleSheet(ERROR_STYLE)
    label.hide()
    return label


def _selectable_label(text: str) -> QtWidgets.QLabel:
    label = QtWidgets.QLabel(text)
    label.setWordWrap(True)
    label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
    return label


def _scrolled(widget: QtWidgets.QWidget) -> QtWidgets.QScrollArea:
    area = QtWidgets.QScrollArea()
    area.setWidget(widget)
    area.setWidgetResizable(True)
    return area
