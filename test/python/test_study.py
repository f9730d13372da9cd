"""Parameter studies (active_tensegrity.study) on a local cluster and on a scheduler with workers started as
separate processes: the results equal the points run one by one; a failing point is recorded, not fatal;
finished points are not run again."""

import csv
import json
import os
import subprocess
import sys
import tempfile
import time

import pytest

import active_tensegrity as at
from active_tensegrity import study

SOURCE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENE = os.path.join(SOURCE, "config", "scenes", "prism_pinned.yaml")

STUDY = """
scene: %s
set: {analysis.steps: 10}
grid:
  analysis.max_actuation: [0.0005, 0.001, 0.002]
  solver.newton_tolerance: [1.0e-8, 1.0e-10]
points:
  - {analysis.max_actuation: 0.5}    # beyond the actuator's range: refused, recorded
collect:
  summary: [status, message, newton_iterations]
  peaks: {max_cable_stress: max, height: min}
  final: [height, actuation]
"""


def write_study(folder):
    path = os.path.join(folder, "prism_study.yaml")
    with open(path, "w") as f:
        f.write(STUDY % SCENE)
    return path


def read_rows(table):
    with open(table) as f:
        return list(csv.DictReader(f))


def check_against_single_runs(rows):
    assert len(rows) == 7
    for row in rows[:6]:
        sets = {"analysis.steps": 10, "analysis.max_actuation": float(row["analysis.max_actuation"]),
                "solver.newton_tolerance": float(row["solver.newton_tolerance"])}
        alone = at.run(SCENE, sets)
        assert row["status"] == alone.summary["status"] == "converged"
        assert int(row["newton_iterations"]) == alone.summary["newton_iterations"]
        assert float(row["final_height"]) == alone["height"][-1]
        assert float(row["min_height"]) == alone["height"].min()
        assert float(row["max_cable_stress"]) == alone["max_cable_stress"].max()
        assert float(row["final_actuation"]) == pytest.approx(sets["analysis.max_actuation"])
    failed = rows[6]
    assert failed["status"] == "refused"
    assert "analysis.max_actuation" in failed["message"] and "0.5" in failed["message"]
    assert failed["final_height"] == ""


def test_a_study_on_a_local_cluster_of_two_workers():
    with tempfile.TemporaryDirectory() as tmp:
        path = write_study(tmp)
        table = study.run_study(path, workers=2, progress=False)
        assert table == os.path.join(tmp, "prism_study", "results.csv")
        check_against_single_runs(read_rows(table))
        # a re-run computes nothing: every point is kept
        kept = os.path.join(tmp, "prism_study", "points")
        before = {f: os.stat(os.path.join(kept, f)).st_mtime_ns for f in os.listdir(kept)}
        assert len(before) == 7
        os.remove(table)
        assert study.run_study(path, workers=2, progress=False) == table
        assert {f: os.stat(os.path.join(kept, f)).st_mtime_ns for f in os.listdir(kept)} == before
        check_against_single_runs(read_rows(table))
        # one point lost: only it runs again
        lost = sorted(before)[0]
        with open(os.path.join(kept, lost)) as f:
            record = json.load(f)
        os.remove(os.path.join(kept, lost))
        study.run_study(path, workers=1, progress=False)
        with open(os.path.join(kept, lost)) as f:
            assert json.load(f) == record
        assert all(os.stat(os.path.join(kept, f)).st_mtime_ns == t for f, t in before.items() if f != lost)


def test_a_study_on_a_scheduler_and_two_worker_processes():
    with tempfile.TemporaryDirectory() as tmp:
        path = write_study(tmp)
        address_file = os.path.join(tmp, "scheduler.json")
        scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                      "--port", "0", "--no-dashboard", "--scheduler-file", address_file],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp)
        workers = []
        try:
            for _ in range(200):
                if os.path.exists(address_file):
                    break
                time.sleep(0.1)
            with open(address_file) as f:
                address = json.load(f)["address"]
            for _ in range(2):
                workers.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                                 "--nthreads", "1", "--no-dashboard", "--no-nanny"],
                                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp))
            from dask.distributed import Client
            with Client(address, timeout=60) as client:
                client.wait_for_workers(2, timeout=60)
                assert len(client.scheduler_info()["workers"]) == 2
            done = subprocess.run([sys.executable, "-m", "active_tensegrity.study", path, "--scheduler", address,
                                   "--no-progress"], capture_output=True, text=True, timeout=600, cwd=tmp)
            assert done.returncode == 0, done.stderr
            table = done.stdout.strip()
            check_against_single_runs(read_rows(table))
        finally:
            for p in workers + [scheduler]:
                p.terminate()
            for p in workers + [scheduler]:
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    p.kill()


def test_a_bad_study_file_is_refused_with_the_key_named():
    with tempfile.TemporaryDirectory() as tmp:
        cases = {
            "scene: nowhere.yaml\ngrid: {analysis.steps: [1]}\n": "scene: no file",
            "scene: %s\ngrid: {analysis.steps: 3}\n" % SCENE: "grid.analysis.steps",
            "scene: %s\n" % SCENE: "no points",
            "scene: %s\ngrid: {analysis.steps: [1]}\ncollect: {peaks: {height: largest}}\n" % SCENE: "collect.peaks",
            "scene: %s\ngrid: {analysis.steps: [1]}\nextra: 1\n" % SCENE: "unknown keys",
        }
        for text, words in cases.items():
            path = os.path.join(tmp, "bad.yaml")
            with open(path, "w") as f:
                f.write(text)
            done = subprocess.run([sys.executable, "-m", "active_tensegrity.study", path, "--no-progress"],
                                  capture_output=True, text=True, timeout=120)
            assert done.returncode == 1 and words in done.stderr, (text, done.stderr)
