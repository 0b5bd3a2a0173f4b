"""The study on several processes: the same samples as in one process, a stop that keeps what is
done, Ctrl-C in a terminal, and workers with one thread each."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from qrfield.simulation import load_study, parallel, run_study

SAMPLE_FIELDS = ("status", "position_mm", "angles_deg", "converged", "iterations", "in_view", "done")
# 5 x 3 x 2 grid points x 12 combinations x 16 angles (0..90 step 6) = 5,760 poses.
STUDY = ["x_range=-80,80,40", "y_range=-40,40,40", "z_range=250,400,150", "sweep_step_deg=6",
         "degradation=round"]  # fmt: skip


@pytest.mark.slow
def test_two_processes_give_the_samples_of_one():
    config = load_study(overrides=STUDY)
    progress = []
    two = run_study(config, workers=2, progress=progress.append, chunk_poses=2000)
    one = run_study(config, workers=1)
    assert not two.partial and two.done.all()
    for name in SAMPLE_FIELDS:
        np.testing.assert_array_equal(getattr(two, name), getattr(one, name), err_msg=name)
    # Progress came from the calling thread, once per task, up to the whole study.
    assert len(progress) > 2 and progress[-1].done_poses == progress[-1].total_poses == 5760
    assert [p.done_poses for p in progress] == sorted(p.done_poses for p in progress)


@pytest.mark.slow
def test_a_stop_keeps_the_finished_tasks_and_marks_the_result_partial():
    config = load_study(overrides=STUDY)
    stop = threading.Event()
    seen = []

    def on_progress(p):
        seen.append(p)
        stop.set()  # as the app's Stop button would, after the first task came back

    result = run_study(config, workers=2, progress=on_progress, stop=stop, chunk_poses=500)
    assert result.partial and 0 < result.done.sum() < result.done.size
    assert result.poses_done == seen[-1].done_poses
    # Every kept grid point has its whole sweep, with the samples of an uninterrupted run.
    full = run_study(config, workers=1)
    done = result.done
    np.testing.assert_array_equal(result.status[:, done], full.status[:, done])
    assert np.all(result.status[:, ~done] == -1)


@pytest.mark.slow
def test_workers_run_one_thread_of_each_library():
    # The workers start with WORKER_ENVIRONMENT, and this process keeps its own environment.
    before = {name: os.environ.get(name) for name in parallel.WORKER_ENVIRONMENT}
    from concurrent.futures import ProcessPoolExecutor

    with parallel.starting_workers():
        pool = ProcessPoolExecutor(1, mp_context=parallel._context(), initializer=parallel._init_worker)
        futures = {name: pool.submit(os.getenv, name) for name in parallel.WORKER_ENVIRONMENT}
    try:
        env = {name: future.result(timeout=60) for name, future in futures.items()}
    finally:
        pool.shutdown()
    assert env == parallel.WORKER_ENVIRONMENT
    assert {name: os.environ.get(name) for name in parallel.WORKER_ENVIRONMENT} == before


def test_small_studies_stay_in_this_process_and_large_ones_use_every_core():
    assert parallel.auto_workers(4680) == 1
    assert parallel.auto_workers(57_960) == parallel.cpu_count()


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a process group is POSIX")
def test_ctrl_c_in_a_terminal_writes_the_partial_study(tmp_path):
    # Ctrl-C reaches the whole process group (the command and its workers): the workers ignore it,
    # the command stops after the tasks in progress and writes what is done.
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "qrfield", "simulate", "--out", str(out), "--no-heatmaps",
           "--workers", "2", "--set", "degradation=round", "--set", "sweep_step_deg=1"]  # fmt: skip
    proc = subprocess.Popen(
        cmd, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        deadline = time.monotonic() + 120
        for line in proc.stderr:  # not a terminal: one progress line per tenth
            if "poses/s" in line or time.monotonic() > deadline:
                break
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["partial"] is True and 0 < summary["samples"] < 7 * 5 * 3 * 12 * 91
    assert "Traceback" not in err


@pytest.mark.slow
def test_the_benchmark_prints_both_paths_and_the_ippe_agreement(capsys):
    from qrfield.cli import main

    tiny = ["--set", "x_range=0", "--set", "y_range=0", "--set", "z_range=300", "--set", "sweep_step_deg=30"]
    assert main(["benchmark", "simulation", *tiny, "--poses", "40"]) == 0
    out = capsys.readouterr().out
    assert "load average" in out and "old (per-pose OpenCV IPPE, one process)" in out
    assert "samples whose verdict differs, new vs old, ippe: 0 of" in out
    assert out.count("mean coverage (within criteria / converged and within criteria)") == 2
    exact = next(line for line in out.splitlines() if line.strip().startswith("exact"))
    assert float(exact.split()[1]) < 1e-6 and float(exact.split()[2]) < 1e-6  # mm, deg
