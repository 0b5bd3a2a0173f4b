"""A clean copy of a session's rows for a spreadsheet or pandas: only the rows still in force.

``rows.csv`` (docs/conventions.md, "Experiment sessions on disk") is an append-only log: a
withdrawn row keeps its line and a withdrawal record (a line with an empty ``row`` and the number
in ``withdraws``) follows it. Read as a table, that log misleads: the withdrawn row looks like any
other and the record is a mostly empty row. :func:`export_session` writes what the session
amounts to now:

- one line per measurement row not withdrawn, in the order logged (withdrawal records and the
  rows they withdraw left out; damaged lines left out, as when the session is opened);
- the columns of rows.csv in its order, without ``withdraws``, each named with its unit:
  ``gt_x_mm``, ``x_mm``, ``err_pos_mm``, ``std_alpha_deg``, ``err_gamma_deg`` ... (see
  :func:`column_with_unit`); ``reprojection_px`` already carries its unit; counts (``n_frames``,
  ``n_converged``, ``mean_iterations``) and ``row``, ``time``, ``combo``, ``pass`` (1 or 0),
  ``note``, ``method`` have none;
- the values exactly as rows.csv holds them (mm and degrees, 3 decimals, a dot as decimal
  separator, empty where there is no pose), UTF-8 without a byte-order mark, comma-separated,
  quoted where a note needs it: read as is by ``csv``, ``pandas.read_csv`` and spreadsheets.

rows.csv itself is never changed. The file is written atomically (a temporary file renamed
over), so a failed export leaves no half file.
"""

from __future__ import annotations

import csv
import errno
import io
import os
from dataclasses import dataclass, field
from pathlib import Path

from qrfield.files import atomic_file, make_folder
from qrfield.sessions.store import ROWS_FILE, SESSION_FILE, SessionError, read_session

#: The unit of each quantity a column name ends with (docs/conventions.md: mm and degrees).
QUANTITY_UNITS = {
    "x": "mm",
    "y": "mm",
    "z": "mm",
    "pos": "mm",
    "alpha": "deg",
    "beta": "deg",
    "gamma": "deg",
}
#: rows.csv columns that only the log needs (left out of the export).
LOG_ONLY_COLUMNS = ("withdraws",)
#: The file name an export gets when it is given a folder.
DEFAULT_NAME = "rows-clean.csv"


def column_with_unit(column: str) -> str:
    """``column`` named with its unit: ``gt_x`` -> ``gt_x_mm``, ``err_alpha`` -> ``err_alpha_deg``,
    ``x`` -> ``x_mm``; a column whose last part is no pose quantity keeps its name."""
    base = column.rpartition("_")[2]
    unit = QUANTITY_UNITS.get(base)
    return f"{column}_{unit}" if unit else column


@dataclass
class CleanTable:
    """The rows in force of one session, ready to write.

    Attributes:
        columns: rows.csv's columns in force (without :data:`LOG_ONLY_COLUMNS`), as in rows.csv.
        header: the same columns named with their units (:func:`column_with_unit`).
        rows: one list of CSV texts per row in force, in ``columns`` order.
        withdrawn: how many measurement rows were left out as withdrawn.
        warnings: what reading rows.csv reported (damaged lines, an unfinished last line).
    """

    columns: list[str]
    header: list[str]
    rows: list[list[str]]
    withdrawn: int = 0
    warnings: list[str] = field(default_factory=list)


def clean_table(folder: str | os.PathLike[str]) -> CleanTable:
    """The rows in force of the session in ``folder``; SessionError if it is not a readable session."""
    _info, content = read_session(folder)
    columns = [c for c in content.columns if c not in LOG_ONLY_COLUMNS]
    rows = [[row.values.get(c, "") for c in columns] for row in content.rows if not row.withdrawn]
    withdrawn = sum(1 for row in content.rows if row.withdrawn)
    return CleanTable(
        columns, [column_with_unit(c) for c in columns], rows, withdrawn, list(content.warnings)
    )


def table_bytes(table: CleanTable) -> bytes:
    """The CSV file's bytes: the header with units, then one line per row ("\\n" line ends)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(table.header)
    writer.writerows(table.rows)
    return buf.getvalue().encode("utf-8")


def export_path(folder: str | os.PathLike[str], out_path: str | os.PathLike[str]) -> Path:
    """Where :func:`export_session` writes: ``out_path``, or ``out_path/rows-clean.csv`` when it is
    an existing folder. SessionError when that is one of the session's own files."""
    target = Path(out_path).expanduser()
    if target.is_dir():
        target = target / DEFAULT_NAME
    session = Path(folder).expanduser()
    for own in (ROWS_FILE, SESSION_FILE):
        if target.resolve() == (session / own).resolve():
            raise SessionError(f"{target}: that is the session's own {own}; export to another file")
    return target


def default_export_path(folder: str | os.PathLike[str]) -> Path:
    """Where an export goes when no file is named: ``rows-clean.csv`` in the session's folder,
    beside ``rows.csv`` (where the app's Export offers to put it)."""
    return Path(folder).expanduser() / DEFAULT_NAME


@dataclass(frozen=True)
class ExportDone:
    """What :func:`write_export` wrote: the file, its rows, the withdrawn rows left out, and what
    reading rows.csv reported."""

    path: Path
    rows: int
    withdrawn: int
    warnings: tuple[str, ...]


def write_export(
    folder: str | os.PathLike[str], out_path: str | os.PathLike[str], *, overwrite: bool = True
) -> ExportDone:
    """Write the rows still in force of the session in ``folder`` to ``out_path`` (see the module
    doc), one row at a time (a session of any size in little memory).

    ``out_path`` may be a file (its folder is created when missing and its parent exists: the
    folder rule of :func:`qrfield.files.make_folder`) or an existing folder (the file is then
    ``rows-clean.csv`` in it, see :func:`export_path`). ``overwrite=False``: FileExistsError when
    the file exists. Raises SessionError when ``folder`` is not a readable session or ``out_path``
    is one of its own files, OSError when the file cannot be written (nothing is left half-written).
    """
    _info, content = read_session(folder)
    target = export_path(folder, out_path)
    if not overwrite and os.path.lexists(target):
        raise FileExistsError(errno.EEXIST, "exists; not overwritten", str(target))
    make_folder(target.parent, "export folder")
    columns = [c for c in content.columns if c not in LOG_ONLY_COLUMNS]
    written = withdrawn = 0
    with atomic_file(target, "w", overwrite=overwrite, newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow([column_with_unit(c) for c in columns])
        for row in content.rows:
            if row.withdrawn:
                withdrawn += 1
                continue
            writer.writerow([row.values.get(c, "") for c in columns])
            written += 1
    return ExportDone(target, written, withdrawn, tuple(content.warnings))


def export_session(
    folder: str | os.PathLike[str], out_path: str | os.PathLike[str], *, overwrite: bool = True
) -> int:
    """:func:`write_export`, returning how many rows were written."""
    return write_export(folder, out_path, overwrite=overwrite).rows
