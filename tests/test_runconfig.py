"""The one run configuration: the file the app saves, read by the commands, options over it, and
``qrfield config`` saying where each value came from."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from qrfield.cli import main
from qrfield.detect import DetectorSettings
from qrfield.runconfig import ConfigStore, RunSettings, effective_settings
from qrfield.serial.link import SerialLinkSettings
from qrfield.solvers import NumericalSettings


def test_config_store_round_trip_and_damage(tmp_path: Path, monkeypatch) -> None:
    store = ConfigStore(tmp_path)
    assert store.group("run", RunSettings) == RunSettings() and store.problems == []
    store.set_group("run", RunSettings(side_mm=30.0, method="ippe"))
    store.save()
    assert ConfigStore(tmp_path).group("run", RunSettings) == RunSettings(side_mm=30.0, method="ippe")
    # A bad value falls back to its default, the good ones stay, and the problem is named.
    (tmp_path / "app.json").write_text(json.dumps({"run": {"side_mm": -5, "method": "ippe", "unknown": 1}}))
    damaged = ConfigStore(tmp_path)
    assert damaged.group("run", RunSettings) == RunSettings(method="ippe")
    assert any("side_mm" in p and "below the minimum" in p for p in damaged.problems)
    (tmp_path / "app.json").write_text("{not json")
    broken = ConfigStore(tmp_path)
    # A file that is not JSON at all is kept aside (issue 15), not overwritten by the defaults later.
    assert broken.group("run", RunSettings) == RunSettings() and "not JSON" in broken.problems[0]
    assert [p.read_text() for p in tmp_path.glob("app.json.bad-*")] == ["{not json"]
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path / "elsewhere"))
    assert ConfigStore().path == tmp_path / "elsewhere" / "app.json"


def test_a_damaged_settings_file_is_kept_aside_with_one_line_and_never_overwritten(tmp_path: Path) -> None:
    # docs/cli.md: a damaged app.json (here nested 5000 levels deep, which json.loads cannot read
    # without a RecursionError) is kept as app.json.bad-<time>, one line says so, defaults are used,
    # and saving writes a fresh file beside the kept one.
    deep = '{"run": ' + "[" * 5000 + "]" * 5000 + "}"
    (tmp_path / "app.json").write_text(deep)
    store = ConfigStore(tmp_path)
    assert store.group("run", RunSettings) == RunSettings()
    assert len(store.problems) == 1 and "\n" not in store.problems[0]
    kept = list(tmp_path.glob("app.json.bad-*"))
    assert len(kept) == 1 and kept[0].name in store.problems[0] and "defaults used" in store.problems[0]
    assert kept[0].read_text() == deep and not (tmp_path / "app.json").exists()
    store.set_group("run", RunSettings(side_mm=30.0))
    store.save()
    assert ConfigStore(tmp_path).group("run", RunSettings).side_mm == 30.0
    assert kept[0].read_text() == deep


def test_a_damaged_settings_file_that_cannot_be_moved_is_not_saved_over(tmp_path: Path, monkeypatch) -> None:
    from qrfield import files

    (tmp_path / "app.json").write_text("[1, 2")

    def refuse(*_args):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(files.os, "rename", refuse)
    store = ConfigStore(tmp_path)
    assert "will not be overwritten" in store.problems[0]
    store.set_group("run", RunSettings(side_mm=30.0))
    store.save()
    assert (tmp_path / "app.json").read_text() == "[1, 2"


def test_saving_settings_follows_no_planted_temporary_file(tmp_path: Path) -> None:
    # The temporary file is made with O_EXCL under a random name (qrfield.files.atomic_write_json):
    # a symlink planted at a predictable name is never written through, and the folder named by
    # --config-dir is made only if its parent exists.
    victim = tmp_path / "victim"
    victim.write_text("mine")
    folder = tmp_path / "config"
    folder.mkdir()
    (folder / "app.json.tmp").symlink_to(victim)
    store = ConfigStore(folder)
    store.set_group("run", RunSettings(side_mm=30.0))
    store.save()
    assert victim.read_text() == "mine"
    assert json.loads((folder / "app.json").read_text())["run"]["side_mm"] == 30.0
    assert not list(folder.glob("tmp*")) and not list(folder.glob(".*tmp*"))
    nowhere = ConfigStore(tmp_path / "no" / "such" / "folder")
    try:
        nowhere.save()
    except FileNotFoundError as exc:
        assert "does not exist" in str(exc)
    else:
        raise AssertionError("a config folder two levels below nothing was created")
    assert not (tmp_path / "no").exists()


def test_commands_say_in_one_line_where_a_damaged_settings_file_went(tmp_path: Path, capsys) -> None:
    (tmp_path / "app.json").write_bytes(b"\xff\xfe not text")
    assert main(["config", "--config-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    problems = [line for line in out.splitlines() if "problem:" in line]
    assert len(problems) == 1 and "kept as app.json.bad-" in problems[0]
    assert len(list(tmp_path.glob("app.json.bad-*"))) == 1


def test_a_file_of_the_older_app_section_is_read_as_the_run_section(tmp_path: Path) -> None:
    old = {
        "app": {
            "source": "virtual",
            "side_mm": 42.0,
            "method": "ippe",
            "plot_window_s": 30,
            "select_text": "g1",
        }
    }
    (tmp_path / "app.json").write_text(json.dumps(old))
    store = ConfigStore(tmp_path)
    assert store.group("run", RunSettings) == RunSettings(source="virtual", side_mm=42.0, method="ippe")
    assert store.group("detector", DetectorSettings).select_text == "g1"  # the one code selection now
    store.save()
    assert "app" not in json.loads((tmp_path / "app.json").read_text())


def write_config(folder: Path, **sections) -> None:
    """Settings groups (all their fields, as the app saves them) or dicts (only those keys)."""
    store = ConfigStore(folder)
    for name, value in sections.items():
        store.set_value(name, value) if isinstance(value, dict) else store.set_group(name, value)
    store.save()


def test_options_override_the_file_which_overrides_the_defaults(tmp_path: Path, capsys) -> None:
    write_config(
        tmp_path,
        run={"side_mm": 40.0, "method": "ippe"},
        numerical=NumericalSettings(tf=0.8),
        serial=SerialLinkSettings(port="/dev/ttyACM3", baud=9600),
    )
    assert main(["config", "--config-dir", str(tmp_path), "--side-mm", "45", "--numerical-n-max", "12"]) == 0
    out = capsys.readouterr().out
    rows = {line.split("=")[0].strip(): line for line in out.splitlines() if "=" in line}
    assert str(tmp_path / "app.json") in out.splitlines()[0]
    assert (
        "45.0 mm" in rows["side_mm"] and "command line" in rows["side_mm"] and "--side-mm" in rows["side_mm"]
    )
    assert "ippe" in rows["method"] and "config file" in rows["method"]
    assert "auto" in rows["source"] and "default" in rows["source"]
    assert "12 " in rows["n_max"] and "command line" in rows["n_max"]
    assert main(["config", "--config-dir", str(tmp_path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["numerical"]["tf"] == {"value": 0.8, "origin": "config file", "option": "--numerical-tf"}
    assert data["serial"]["baud"]["value"] == 9600 and data["camera_model"]["width"] == 640


@pytest.mark.slow
def test_serial_without_a_port_takes_the_configured_one(tmp_path: Path) -> None:
    import argparse

    from qrfield.runconfig import add_run_arguments

    write_config(tmp_path, serial=SerialLinkSettings(port="/dev/ttyACM3", baud=9600))
    parser = argparse.ArgumentParser()
    add_run_arguments(parser)
    chosen = effective_settings(parser.parse_args(["--config-dir", str(tmp_path), "--serial"]))
    assert chosen.serial_settings() == SerialLinkSettings(port="/dev/ttyACM3", baud=9600)
    given = effective_settings(parser.parse_args(["--config-dir", str(tmp_path), "--serial", "loop://"]))
    assert given.serial_settings().port == "loop://" and given.origin("serial", "port") == "command line"
    assert effective_settings(parser.parse_args(["--config-dir", str(tmp_path)])).serial_port is None


def test_serial_without_a_port_never_streams_into_the_simulated_port(tmp_path: Path, capsys) -> None:
    """audit-1: `qrfield run --serial` on a machine whose app never set a port streamed to loop://
    (the default, and what the app saves when its Serial tab was never touched), said "connected"
    and exited 0, while the controller on /dev/ttyUSB0 got nothing."""
    fresh, saved = tmp_path / "fresh", tmp_path / "saved"
    write_config(saved, serial=SerialLinkSettings())  # every field, as the app saves it on close
    assert json.loads((saved / "app.json").read_text())["serial"]["port"] == "loop://"
    for folder in (fresh, saved):
        run = ["run", "--config-dir", str(folder), "--source", "virtual", "--frames", "1"]
        assert main([*run, "--serial"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--serial without PORT" in err and "give --serial PORT" in err
        assert str(folder / "app.json") in err and "loop://" in err and "connected" not in err
    # Named on the command line, loop:// is a choice (a test): it runs.
    run = ["run", "--config-dir", str(fresh), "--source", "virtual", "--frames", "1"]
    assert main([*run, "--serial", "loop://"]) == 0
    assert main([*run, "--serial", "--serial-port", "loop://"]) == 0
    assert "serial loop://: connected" in capsys.readouterr().err


def test_run_measures_with_the_configured_settings_and_notes_an_assumed_side(tmp_path: Path, capsys) -> None:
    from qrfield.camera import resolve_camera
    from qrfield.geometry import Pose
    from qrfield.render import render_view

    folder = tmp_path / "images"
    folder.mkdir()
    camera = resolve_camera("picam-v2@640x480")
    pose = Pose([0.0, 0.0, 320.0], [10.0, -5.0, 30.0])
    cv2.imwrite(str(folder / "a.png"), render_view(camera, 40.0, pose, noise_sigma=1.0, seed=3).image)
    # No file: a 50 mm code is assumed, and the run says so (a 40 mm card then reads 25 % too far).
    assert main(["run", "--config-dir", str(tmp_path / "none"), "--source", str(folder), "--json-lines"]) == 0
    out = capsys.readouterr()
    assert "QR side: 50 mm assumed" in out.err and "camera model: picam-v2@640x480 assumed" in out.err
    z_assumed = json.loads(out.out.splitlines()[0])["position_mm"][2]
    assert abs(z_assumed / 320.0 - 50.0 / 40.0) < 0.02
    # The app's saved side and method are used, and nothing is said to be assumed.
    write_config(tmp_path / "cfg", run=RunSettings(side_mm=40.0, method="ippe"))
    args = ["run", "--config-dir", str(tmp_path / "cfg"), "--source", str(folder), "--json-lines"]
    assert main(args) == 0
    out = capsys.readouterr()
    line = json.loads(out.out.splitlines()[0])
    assert line["method"] == "ippe" and "methods" not in line
    assert np.linalg.norm(np.array(line["position_mm"]) - pose.position_mm) < 5.0
    assert "assumed" not in out.err  # the app saved both (RunSettings holds the camera too)


def test_the_run_configuration_has_the_one_side_option_and_its_limits(tmp_path: Path, capsys) -> None:
    # The run configuration's --side-mm is qrfield.arguments.add_side_argument (issue 15): refused
    # at the option against qrfield.limits.SIDE_MM (0.1 mm .. 10 m), for run, config and session.
    for argv, said in (
        (["config", "--side-mm", "1e-300"], "below the smallest accepted, 0.1 mm"),
        (["run", "--source", "virtual", "--frames", "1", "--side-mm", "nan"], "must be a finite number"),
        (["session", "new", str(tmp_path), "--name", "s", "--side-mm", "2e4"], "above the largest accepted"),
    ):
        assert main([*argv, "--config-dir", str(tmp_path)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "argument --side-mm" in err and said in err
    # A small code of 0.5 mm is a real one (the setting's old floor was 1 mm): from the command line.
    assert main(["config", "--config-dir", str(tmp_path), "--json", "--side-mm", "0.5"]) == 0
    side = json.loads(capsys.readouterr().out)["run"]["side_mm"]
    assert side == {"value": 0.5, "origin": "command line", "option": "--side-mm"}


def test_config_dir_also_holds_the_users_camera_profiles(tmp_path, capsys, monkeypatch) -> None:
    """`--config-dir D` is the config folder for everything in it, the user's calibrations in
    D/calib included: `--camera mycam` finds D/calib/mycam.json (it used to look in the default)."""
    from qrfield.cli import main

    folder = tmp_path / "bench-pi"
    (folder / "calib").mkdir(parents=True)
    profile = {"width": 640, "height": 480, "fx": 612.5, "fy": 611.0, "cx": 319.5, "cy": 239.5}
    (folder / "calib" / "mycam.json").write_text(json.dumps(profile), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    code = main(["config", "--config-dir", "bench-pi", "--camera", "mycam", "--json"])
    shown = capsys.readouterr()
    assert code == 0, shown.err
    shown = shown.out
    assert "612.5" in shown and "mycam" in shown
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path / "elsewhere"))  # a new process without it
    assert main(["config", "--camera", "mycam", "--json"]) == 2  # not found
    assert "mycam" in capsys.readouterr().err


def test_one_absurd_value_costs_only_its_own_key_and_stops_a_strict_run(tmp_path: Path, capsys) -> None:
    # A 500-digit integer (and one of 5000 digits, over Python's int() limit) or a text over the
    # csv field limit in app.json once set the whole file aside: every saved setting was lost for
    # one bad value. Each is now left out alone, named, its default used; `qrfield run` refuses it.
    big, huge = "1" + "0" * 500, "1" + "0" * 5000
    text = (
        f'{{"run": {{"side_mm": {big}, "method": "ippe"}}, "detector": {{"max_codes": {huge}, '
        f'"search_px": 3.0}}, "window": {{"w": 5, "x": "{"a" * 200_000}"}}}}'
    )
    (tmp_path / "app.json").write_text(text)
    store = ConfigStore(tmp_path)
    assert store.group("run", RunSettings) == RunSettings(method="ippe")
    assert store.group("detector", DetectorSettings) == DetectorSettings(search_px=3.0)
    assert store.value("window") == {"w": 5}
    assert not list(tmp_path.glob("app.json.bad-*"))
    assert sorted(store.dropped) == ["detector.max_codes", "run.side_mm", "window.x"]
    assert any("run.side_mm" in p and "501 digits" in p and "default used" in p for p in store.problems)
    assert any("detector.max_codes" in p and "5001 digits" in p for p in store.problems)
    assert main(["run", "--config-dir", str(tmp_path), "--source", "virtual"]) != 0
    assert "run.side_mm" in capsys.readouterr().err
