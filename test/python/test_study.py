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
        assert float(row["min_height_t"]) == alone["t"][alone["height"].argmin()]  # a static path: a row per step
        assert float(row["max_cable_stress"]) == alone["max_cable_stress"].max()
        assert float(row["max_cable_stress_t"]) == alone["t"][alone["max_cable_stress"].argmax()]
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
            "scene: %s\ngrid: {analysis.steps: [1, 2]}\nsave: {name: run}\n" % SCENE: "both give the name 'run'",
            "scene: %s\ngrid: {analysis.steps: [1]}\nsave: {name: 'r{struts.radius}'}\n" % SCENE:
                "no value for {struts.radius}",
            "scene: %s\ngrid: {analysis.steps: [1]}\nsave: {name: r, files: [table, bag]}\n" % SCENE: "save.files",
            "scene: %s\ngrid: {analysis.steps: [1]}\nplots: [{x: t, y: height}]\n" % SCENE: "plots[0]",
            "scene: %s\ngrid: {analysis.steps: [1]}\ncollect: {summary: [peaks]}\n" % SCENE: "'peaks' is a mapping",
            "scene: %s\ngrid: {analysis.steps: [1]}\ncollect: {summary: [wall]}\n" % SCENE:
                "unknown summary field 'wall'",
        }
        for text, words in cases.items():
            path = os.path.join(tmp, "bad.yaml")
            with open(path, "w") as f:
                f.write(text)
            done = subprocess.run([sys.executable, "-m", "active_tensegrity.study", path, "--no-progress"],
                                  capture_output=True, text=True, timeout=120)
            assert done.returncode == 1 and words in done.stderr, (text, done.stderr)


SAVING = """
scene: %s
set: {analysis.steps: 8}
points:
  - {analysis.max_actuation: 0.001}
  - {analysis.max_actuation: 0.002, solver.newton_tolerance: 1.0e-10}
  - {analysis.max_actuation: 0.5}    # refused: no files
collect:
  summary: [status, message, newton_iterations, output_steps]
  peaks: {max_cable_stress: max, height: min}
  final: [height]
save:
  name: "prism_h{analysis.max_actuation}"
  files: [table, summary, members]
plots:
  - {x: analysis.max_actuation, y: [min_height, final_height], file: heights.png}
"""

# summary lines that differ from run to run (timings) or name the scene file as given
VARYING = ("scene:", "wall_time:", "real_time_factor:", "time_breakdown:", "  forces:", "  contact:", "  constraints:",
           "  factorization:", "  solve:", "  solver_other:", "  callbacks:", "  rest:")


def steady(text):
    return [line for line in text.splitlines() if not line.startswith(VARYING)]


def test_saved_files_are_those_of_tensegrity_run_and_the_collected_values_those_of_the_api():
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "saving.yaml")
        with open(path, "w") as f:
            f.write(SAVING % SCENE)
        out = os.path.join(tmp, "out")
        table = study.run_study(path, out=out, workers=2, progress=False)
        rows = read_rows(table)
        assert [r["status"] for r in rows] == ["converged", "converged", "refused"]
        assert sorted(f for f in os.listdir(out) if f != "points") == sorted(
            ["results.csv", "heights.png"] + ["prism_h%s%s" % (h, s) for h in ("0.001", "0.002")
                                               for s in (".csv", ".yaml", "_members.csv")])
        program = study.tensegrity_run()
        for row, tolerance in zip(rows[:2], ("1e-06", "1e-10")):
            stem = os.path.join(out, "prism_h" + row["analysis.max_actuation"])
            sets = ["analysis.steps=8", "analysis.max_actuation=" + row["analysis.max_actuation"]]
            if tolerance != "1e-06":
                sets.append("solver.newton_tolerance=" + tolerance)
            by_hand = os.path.join(tmp, "by_hand")
            command = [program, SCENE, "--out", by_hand + ".csv", "--summary", by_hand + ".yaml", "--members",
                       by_hand + "_members.csv"]
            for s in sets:
                command += ["--set", s]
            subprocess.run(command, check=True, capture_output=True)
            for suffix in (".csv", "_members.csv"):
                with open(stem + suffix) as a, open(by_hand + suffix) as b:
                    assert a.read() == b.read(), suffix
            with open(stem + ".yaml") as a, open(by_hand + ".yaml") as b:
                saved, hand = a.read(), b.read()
            assert steady(saved) == steady(hand)
            assert saved.startswith("scene: %s\n" % SCENE)  # the study's scene, not the worker's copy
            # what was collected: as the in-process API gives it, to the digits tensegrity_run prints (10)
            alone = at.run(SCENE, dict(s.split("=") for s in sets))
            printed = lambda x: float("%.10g" % x)  # noqa: E731
            assert int(row["newton_iterations"]) == alone.summary["newton_iterations"]
            assert int(row["output_steps"]) == alone.summary["output_steps"]
            assert float(row["final_height"]) == printed(alone["height"][-1])
            assert float(row["min_height"]) == printed(alone["height"].min())
            assert float(row["max_cable_stress"]) == printed(alone["max_cable_stress"].max())
        assert "analysis.max_actuation" in rows[2]["message"]
        # kept: a re-run runs nothing; a saved file written over by something else runs its point again
        kept = os.path.join(out, "points")
        before = {f: os.stat(os.path.join(kept, f)).st_mtime_ns for f in os.listdir(kept)}
        study.run_study(path, out=out, workers=1, progress=False)
        assert {f: os.stat(os.path.join(kept, f)).st_mtime_ns for f in os.listdir(kept)} == before
        with open(os.path.join(out, "prism_h0.001.csv"), "a") as f:
            f.write("0,0\n")
        study.run_study(path, out=out, workers=1, progress=False)
        after = {f: os.stat(os.path.join(kept, f)).st_mtime_ns for f in os.listdir(kept)}
        assert sum(after[f] != before[f] for f in before) == 1
        with open(os.path.join(out, "prism_h0.001.csv")) as a, open(os.path.join(out, "prism_h0.002.csv")) as b:
            assert not a.read().endswith("0,0\n")


def test_set_overrides_every_point_and_the_shipped_studies_run():
    with tempfile.TemporaryDirectory() as tmp:
        # the quadruplex radius study as shipped, shortened to 10 load steps by --set over every point
        shipped = os.path.join(SOURCE, "config", "studies", "quadruplex_contact.yaml")
        done = subprocess.run([sys.executable, "-m", "active_tensegrity.study", shipped, "--out", tmp, "--workers", "2",
                               "--set", "analysis.steps=10", "--set", "analysis.max_actuation=0.25", "--no-progress"],
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        rows = read_rows(os.path.join(tmp, "results.csv"))
        assert [r["struts.radius"] for r in rows] == ["0.04", "0.05", "0.06", "0.07", "0.08"]
        assert all(r["status"] == "converged" and float(r["final_actuation"]) == 0.25 for r in rows)
        for r in rows:
            with open(os.path.join(tmp, "contact_r%s.csv" % r["struts.radius"])) as f:
                assert len(f.read().splitlines()) == 12  # the header, the start and 10 load steps
        assert os.path.getsize(os.path.join(tmp, "peak_contact_force.png")) > 0
        # every shipped study reads, and names its points' files as the scripts expect
        names = {"tower_quasi_static.yaml": ["static_contact_true", "static_contact_false"],
                 "tower_dynamic.yaml": ["dynamic_v0.005", "dynamic_v5", "dynamic_v2", "dynamic_v0.5", "dynamic_v0.05"],
                 "quadruplex_no_contact.yaml": ["no_contact_r%s" % r for r in ("0.04", "0.05", "0.06", "0.07", "0.08")]}
        for name, stems in names.items():
            assert study.read_study(os.path.join(SOURCE, "config", "studies", name))["save"]["stems"] == stems
        bad = subprocess.run([sys.executable, "-m", "active_tensegrity.study", shipped, "--out", tmp, "--set",
                              "analysis.steps"], capture_output=True, text=True, timeout=120)
        assert bad.returncode == 1 and "--set: expected KEY=VALUE" in bad.stderr
