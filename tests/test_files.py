"""qrfield.files: bounded, BOM-tolerant, depth-checked reading; atomic writes; folders; damaged files."""

from __future__ import annotations

import json
import os
import stat
import tempfile
from pathlib import Path

import pytest

from qrfield import files
from qrfield.files import (
    MAX_DEPTH,
    MAX_FIELD_CHARS,
    Fields,
    FileFormatError,
    atomic_file,
    atomic_write,
    make_folder,
    nesting_depth,
    read_json,
    read_json_or_set_aside,
    read_toml,
)


@pytest.fixture(autouse=True)
def _own_folders(tmp_path, monkeypatch):
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path / "own-config"))
    monkeypatch.setenv("QRFIELD_DATA_DIR", str(tmp_path / "own-data"))


# ---------------------------------------------------------------------------------------- reading
def test_a_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "x.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps({"a": 1}).encode())
    assert read_json(path, "test file") == {"a": 1}
    toml = tmp_path / "x.toml"
    toml.write_bytes(b"\xef\xbb\xbfa = 1\n")
    assert read_toml(toml, "test file") == {"a": 1}


@pytest.mark.parametrize("depth", [MAX_DEPTH + 1, 100_000])
def test_deep_nesting_is_refused_before_parsing_never_recursion_error(tmp_path, depth):
    path = tmp_path / "deep.json"
    path.write_text("[" * depth + "]" * depth)
    with pytest.raises(FileFormatError, match=rf"test file {path}: nested {depth} levels deep"):
        read_json(path, "test file")
    toml = tmp_path / "deep.toml"
    toml.write_text("a = " + "[" * depth + "]" * depth + "\n")
    with pytest.raises(FileFormatError, match="nested"):
        read_toml(toml, "test file")


def test_depth_at_the_limit_is_read_and_brackets_in_strings_do_not_count(tmp_path):
    path = tmp_path / "ok.json"
    path.write_text("[" * MAX_DEPTH + "]" * MAX_DEPTH)
    assert read_json(path, "f") is not None
    assert nesting_depth('{"a": "[[[[[[[[[[", "b": ["\\"[["]}') == 2
    assert nesting_depth('a = "[[[" # [[[[[\nb = [[1]]\nc = """\n[[[[\n"""', "toml") == 2


def test_an_unclosed_string_does_not_make_the_scan_quadratic():
    # '"\\' repeated: every quote opens a string that never closes; the scan must stay linear
    # (a backtracking pattern took minutes here).
    text = '"\\' * 200_000
    assert nesting_depth(text) == 0 and nesting_depth(text, "toml") == 0


def test_a_field_longer_than_the_csv_limit_is_refused(tmp_path):
    path = tmp_path / "long.json"
    path.write_text(json.dumps({"notes": "x" * (MAX_FIELD_CHARS + 1)}))
    with pytest.raises(FileFormatError, match=r"value notes is 131073 characters long"):
        read_json(path, "f")


def test_size_limit_folders_fifos_and_missing_files_are_one_line(tmp_path):
    big = tmp_path / "big.json"
    big.write_bytes(b" " * 2048)
    with pytest.raises(FileFormatError, match="larger than") as exc:
        read_json(big, "f", max_bytes=1024)
    assert exc.value.kind == "unreadable"
    with pytest.raises(FileFormatError, match="is a folder"):
        read_json(tmp_path, "f")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(FileFormatError, match="not a regular file"):  # must not wait for a writer
        read_json(fifo, "f")
    with pytest.raises(FileFormatError, match="no such file") as exc:
        read_json(tmp_path / "none.json", "f")
    assert exc.value.kind == "missing"
    bad = tmp_path / "bad.json"
    bad.write_bytes(b"\xff\xfe{}")
    with pytest.raises(FileFormatError, match="not UTF-8"):
        read_json(bad, "f")
    bad.write_text('{"a": NaN}')
    with pytest.raises(FileFormatError, match="not JSON"):
        read_json(bad, "f")


def test_fields_name_the_value_of_the_wrong_type():
    fields = Fields({"side_mm": "50", "name": 3, "camera": [], "n": 2.5}, "session file s.json")
    with pytest.raises(FileFormatError, match=r"s.json: field 'side_mm' must be a number, got text '50'"):
        fields.number("side_mm")
    with pytest.raises(FileFormatError, match=r"field 'name' must be text, got 3"):
        fields.text("name")
    with pytest.raises(FileFormatError, match=r"field 'camera' must be a JSON object, got a list of 0"):
        fields.mapping("camera")
    with pytest.raises(FileFormatError, match=r"field 'n' must be a whole number"):
        fields.integer("n")
    with pytest.raises(FileFormatError, match=r"missing field 'fx'"):
        fields.number("fx")
    with pytest.raises(FileFormatError, match="expected a JSON object, got a list"):
        Fields([1], "f")


# ---------------------------------------------------------------------------------------- writing
def test_atomic_write_replaces_all_or_nothing_and_keeps_the_mode(tmp_path, monkeypatch):
    path = tmp_path / "profile.json"
    path.write_text("old\n")
    path.chmod(0o640)
    atomic_write(path, "new\n")
    assert path.read_text() == "new\n" and stat.S_IMODE(path.stat().st_mode) == 0o640

    def disk_full(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(files.os, "fsync", disk_full)
    with pytest.raises(OSError, match="No space"):
        atomic_write(path, "half\n")
    assert path.read_text() == "new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["profile.json"]  # no temporary file left


def _unwritable_folder(tmp_path: Path, monkeypatch) -> Path:
    """A folder in which no file can be made: the kernel's /sys refuses even root; elsewhere a
    folder whose mkstemp raises what a read-only medium raises (EROFS, naming the temporary file)."""
    sys_root = Path("/sys")
    if sys_root.is_dir() and not os.access(sys_root, os.W_OK | os.X_OK):
        return sys_root
    made = tmp_path / "read-only"
    made.mkdir()

    def read_only(*args, dir=None, prefix="", suffix="", **kwargs):
        raise OSError(30, "Read-only file system", os.path.join(str(dir), f"{prefix}u_1_5t6s{suffix}"))

    monkeypatch.setattr(files.tempfile, "mkstemp", read_only)
    return made


def test_a_target_that_cannot_be_written_is_named_not_its_temporary_file(tmp_path, monkeypatch):
    """audit-1: `session export` to a read-only medium said
    "error: .../.rows-clean.csv.u_1_5t6s.tmp: read-only file system", a name the user never gave."""
    target = _unwritable_folder(tmp_path, monkeypatch) / "rows-clean.csv"
    with pytest.raises(OSError) as caught:
        atomic_write(target, "row\n")
    assert caught.value.filename == str(target)
    message = files.describe_error(caught.value)
    assert message.startswith(f"{target}: ") and ".tmp" not in message
    assert not target.exists()


def test_temporary_names_are_unpredictable_and_a_planted_symlink_is_not_followed(tmp_path, monkeypatch):
    # The old writer used ".NAME.tmp-<pid>": anyone could plant a symlink there to a file of the
    # user's and have it overwritten. mkstemp's names are random and it opens with O_EXCL.
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    target = tmp_path / "out.json"
    for guess in (f".out.json.tmp-{os.getpid()}", "out.json.tmp", ".out.json.tmp"):
        (tmp_path / guess).symlink_to(victim)
    names = []
    real_mkstemp = tempfile.mkstemp

    def spy(*args, **kwargs):
        fd, name = real_mkstemp(*args, **kwargs)
        names.append(Path(name).name)
        return fd, name

    monkeypatch.setattr(files.tempfile, "mkstemp", spy)
    atomic_write(target, "data\n")
    atomic_write(target, "data 2\n")
    assert victim.read_text() == "precious\n" and target.read_text() == "data 2\n"
    assert len(set(names)) == 2 and all(n.startswith(".out.json.") for n in names)
    # A symlink at the target itself is replaced by the file, never written through.
    link = tmp_path / "link.json"
    link.symlink_to(victim)
    atomic_write(link, "replaced\n")
    assert victim.read_text() == "precious\n" and not link.is_symlink()


def test_no_overwrite_refuses_an_existing_file(tmp_path):
    path = tmp_path / "card.svg"
    atomic_write(path, "a", overwrite=False)
    with pytest.raises(FileExistsError):
        atomic_write(path, "b", overwrite=False)
    with pytest.raises(FileExistsError), atomic_file(path, "w", overwrite=False) as handle:
        handle.write("c")
    assert path.read_text() == "a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["card.svg"]


def test_writers_never_create_the_folder_of_a_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"folder .*missing does not exist"):
        atomic_write(tmp_path / "missing" / "x.json", "{}")
    assert not (tmp_path / "missing").exists()
    with pytest.raises(IsADirectoryError):
        atomic_write(tmp_path, "{}")


def test_make_folder_creates_the_named_folder_but_none_above_it(tmp_path):
    assert make_folder(tmp_path / "out").is_dir()
    with pytest.raises(FileNotFoundError, match="does not exist"):
        make_folder(tmp_path / "a" / "b" / "out")
    assert not (tmp_path / "a").exists()
    (tmp_path / "file").write_text("")
    with pytest.raises(NotADirectoryError, match="is a file"):
        make_folder(tmp_path / "file" / "out")
    # qrfield's own folders (config, data) are made with their parents.
    own = tmp_path / "own-data" / "sessions" / "deep"
    assert make_folder(own).is_dir()


# ---------------------------------------------------------------------------------------- damaged
def test_a_damaged_settings_file_is_kept_aside_with_one_line(tmp_path):
    path = tmp_path / "app.json"
    path.write_text("[" * 5000 + "]" * 5000)  # once a RecursionError that stopped the app
    loaded = read_json_or_set_aside(path)
    assert loaded.data is None and loaded.damaged and loaded.safe_to_overwrite
    assert loaded.kept_as is not None and loaded.kept_as.name.startswith("app.json.bad-")
    assert not path.exists() and loaded.kept_as.read_text().startswith("[[[")
    assert "\n" not in loaded.problem and f"kept as {loaded.kept_as.name}" in loaded.problem
    assert "defaults used" in loaded.problem
    # A second damaged file gets its own name (no copy is overwritten).
    path.write_text("not json")
    again = read_json_or_set_aside(path)
    assert again.kept_as is not None and again.kept_as != loaded.kept_as and loaded.kept_as.exists()


def test_settings_file_missing_good_wrong_type_and_unmovable(tmp_path, monkeypatch):
    path = tmp_path / "app.json"
    assert read_json_or_set_aside(path).data is None and not read_json_or_set_aside(path).problem
    path.write_text('{"app": {"side_mm": 40}}')
    assert read_json_or_set_aside(path).data == {"app": {"side_mm": 40}}
    path.write_text("[1, 2]")
    loaded = read_json_or_set_aside(path)
    assert loaded.damaged and "expected a JSON object" in loaded.problem and loaded.kept_as is not None
    path.write_text("{")

    def read_only(src, dst):  # a read-only folder (chmod would not stop root, who runs CI)
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(files.os, "rename", read_only)
    loaded = read_json_or_set_aside(path)
    assert loaded.damaged and not loaded.safe_to_overwrite and "could not keep it aside" in loaded.problem
    assert path.read_text() == "{"


def test_atomic_write_json_is_what_a_config_store_saves(tmp_path):
    # How qrfield.runconfig.ConfigStore.save writes app.json (docs/cli.md; tests/test_runconfig.py).
    from qrfield.files import atomic_write_json

    path = tmp_path / "app.json"
    data = {"window": {"w": 800}, "app": {"side_mm": 50.0}}
    atomic_write_json(path, data, sort_keys=True)
    assert path.read_text() == json.dumps(data, indent=2, sort_keys=True) + "\n"
    assert read_json_or_set_aside(path).data == data
