"""A study's peaks are over every step of a run, not over its output rows: on the impact scene, whose contact
lasts about 0.5 ms, rows every 0.5 ms or 1 ms miss most of the impact force. Each collected peak is checked
against the same scene run with a row per step (analysis.output_interval 0: the fixed-step loop takes the same
steps and writes every one of them), its column's largest or smallest value found here with numpy."""

import csv
import json
import os
import tempfile

import numpy as np
import pytest

import active_tensegrity as at
from active_tensegrity import study

SOURCE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
IMPACT = os.path.join(SOURCE, "config", "scenes", "impact.yaml")
PRISM = os.path.join(SOURCE, "config", "scenes", "prism_pinned.yaml")

# the peaks asked for: CSV columns (one a max that the run summary's own peaks track, one never negative that
# they do not, one that is negative), a min of each kind and a member column (a holding spring's tension)
PEAKS = {"max_normal_force": "max", "min_gap": "min", "height": "min", "active_contacts": "max",
         "HA2_tension": "max", "A_force": "min"}

STUDY = """
scene: %s
points:
  - {analysis.output_interval: 0.0005}
  - {analysis.output_interval: 0.001}
collect:
  summary: [status, output_steps, solver_steps]
  peaks: %s
  final: [height]
"""


def every_step():
    """The impact run with a row per step, and {column: its values} over the CSV's and the members' columns."""
    r = at.run(IMPACT, {"analysis.output_interval": 0})
    assert r.summary["output_steps"] == r.summary["solver_steps"] + 1
    return {c: r[c] for c in r.columns + r.member_columns}


def extreme(rows, column, kind):
    values = rows[column]
    i = int(np.argmax(values) if kind == "max" else np.argmin(values))
    return values[i], rows["t"][i]


def write(folder, text, name="peaks.yaml"):
    path = os.path.join(folder, name)
    with open(path, "w") as f:
        f.write(text)
    return path


def read_rows(table):
    with open(table) as f:
        return list(csv.DictReader(f))


def test_the_rows_of_a_coarse_output_miss_the_impact():
    # what the study took before: the largest value over the output rows, far below the impact's force
    rows = every_step()
    coarse = at.run(IMPACT, {"analysis.output_interval": 0.0005})
    assert coarse["max_normal_force"].max() < 0.8 * rows["max_normal_force"].max()
    assert at.run(IMPACT, {"analysis.output_interval": 0.001})["max_normal_force"].max() == 0.0


def test_run_tracks_the_extremes_of_every_step():
    rows = every_step()
    r = at.run(IMPACT, {"analysis.output_interval": 0.001}, extremes=list(PEAKS) + ["t"])
    assert r.summary["output_steps"] == 151 and r.summary["solver_steps"] == 1500
    for column in PEAKS:
        for kind in ("max", "min"):
            value, t = extreme(rows, column, kind)
            assert r.extremes[column][kind] == {"value": value, "t": t}, (column, kind)
        assert r.extremes[column]["states"] == 1501
    assert r.extremes["t"]["max"]["value"] == 0.15 and r.extremes["t"]["min"]["value"] == 0.0
    # the summary's peaks (largest magnitude, tracked apart) agree where they overlap
    assert r.summary["peaks"]["max_normal_force"]["value"] == r.extremes["max_normal_force"]["max"]["value"]
    with pytest.raises(ValueError) as unknown:
        at.run(IMPACT, extremes=["no_such_column"])
    assert "no_such_column" in str(unknown.value) and "min_gap" in str(unknown.value)
    with pytest.raises(TypeError):
        at.run(IMPACT, extremes=[1])


@pytest.mark.parametrize("scene, sets", [
    ("impact.yaml", {}),
    ("six_bar.yaml", {"analysis.duration": 1.0}),  # the ground's columns
    ("tower.yaml", {"analysis.type": "dynamic", "analysis.duration": 0.5, "actuation.speed": 2}),  # 4 actuators, layers
    ("quadruplex.yaml", {"contact.enabled": True, "analysis.steps": 60}),  # a static path with contact
    ("masts.yaml", {}),
])
def test_the_extremes_of_every_column_are_those_of_a_row_per_step(scene, sets):
    # run() computes each tracked column alone (not the whole row) at every step: every column of the CSV and
    # of the members' table, against the rows of a run that writes every step
    path = os.path.join(SOURCE, "config", "scenes", scene)
    model = at.load(path, dict(sets, **{"analysis.output_interval": 0}))
    r = at.run(model, extremes=model.columns + model.member_columns)
    assert r.summary["status"] == "converged"
    assert len(r["t"]) == r.extremes["t"]["states"] == (r.summary["output_steps"])
    for column in model.columns + model.member_columns:
        values = r[column]
        for kind in ("max", "min"):
            i = int(np.argmax(values) if kind == "max" else np.argmin(values))
            assert r.extremes[column][kind] == {"value": values[i], "t": r["t"][i]}, (column, kind)


def test_an_adaptive_run_tracks_the_extremes_of_every_accepted_step():
    # adaptive steps stop at the output times (a row per step is another run): the extremes are checked against
    # the summary's peak, which the core tracks apart (its own contact scan), and against the rows
    r = at.run(IMPACT, {"solver.adaptive": True, "analysis.output_interval": 0.001}, extremes=["max_normal_force"])
    tracked = r.extremes["max_normal_force"]["max"]
    assert tracked == r.summary["peaks"]["max_normal_force"]
    assert tracked["value"] > 2 * r["max_normal_force"].max()
    assert r.extremes["max_normal_force"]["states"] == r.summary["solver_steps"] + 1


def check_point(row, rows, exact):
    assert row["status"] == "converged"
    for column, kind in PEAKS.items():
        name = study.peak_column(column, kind)
        value, t = extreme(rows, column, kind)
        if exact:
            assert float(row[name]) == value, (name, row[name], value)
        else:  # from tensegrity_run's files, to the ten digits they print, or tracked in-process
            assert float(row[name]) == pytest.approx(value, rel=1e-9, abs=1e-12), (name, row[name], value)
        assert float(row[name + "_t"]) == pytest.approx(t, abs=1e-12), (name, row[name + "_t"], t)
    assert float(row["final_height"]) == pytest.approx(rows["height"][-1], rel=1e-9)


def test_a_studys_peaks_are_those_of_every_step_in_process_and_saved():
    rows = every_step()
    with tempfile.TemporaryDirectory() as tmp:
        path = write(tmp, STUDY % (IMPACT, json.dumps(PEAKS)))
        table = study.run_study(path, workers=1, progress=False)
        got = read_rows(table)
        assert [r["analysis.output_interval"] for r in got] == ["0.0005", "0.001"]
        assert [int(r["output_steps"]) for r in got] == [301, 151]
        for row in got:
            check_point(row, rows, exact=True)
        # the same points through tensegrity_run, their files saved
        saving = STUDY % (IMPACT, json.dumps(PEAKS)) + 'save: {name: "impact_{analysis.output_interval}"}\n'
        path = write(tmp, saving, "saving.yaml")
        table = study.run_study(path, workers=1, progress=False)
        saved = read_rows(table)
        for row in saved:
            check_point(row, rows, exact=False)
        # the saved table itself misses the impact: the peak is not the table's
        with open(os.path.join(tmp, "saving", "impact_0.001.csv")) as f:
            written = list(csv.DictReader(f))
        assert max(float(r["max_normal_force"]) for r in written) == 0.0
        assert float(saved[1]["max_normal_force"]) > 40e3


def test_a_row_per_step_or_a_static_path_takes_its_peaks_from_its_files():
    # every step is a row: the files give every peak, the extremes of their rows
    with tempfile.TemporaryDirectory() as tmp:
        text = """
scene: %s
points:
  - {analysis.output_interval: 0}
collect:
  peaks: {height: min, min_gap: min, max_normal_force: max}
save: {name: impact_every_step, files: [table]}
""" % IMPACT
        table = study.run_study(write(tmp, text), workers=1, progress=False)
        row = read_rows(table)[0]
        with open(os.path.join(tmp, "peaks", "impact_every_step.csv")) as f:
            written = list(csv.DictReader(f))
        for column, kind in (("height", "min"), ("min_gap", "min"), ("max_normal_force", "max")):
            values = [float(r[column]) for r in written]
            assert float(row[study.peak_column(column, kind)]) == (max(values) if kind == "max" else min(values))
        text = """
scene: %s
set: {analysis.steps: 7}
points: [{analysis.max_actuation: 0.002}]
collect: {peaks: {height: min, max_cable_stress: max, actuation_force: min}}
save: {name: prism, files: [table]}
""" % PRISM
        table = study.run_study(write(tmp, text, "static.yaml"), workers=1, progress=False)
        row = read_rows(table)[0]
        alone = at.run(PRISM, {"analysis.steps": 7, "analysis.max_actuation": 0.002})
        printed = lambda x: float("%.10g" % x)  # noqa: E731
        assert float(row["min_height"]) == printed(alone["height"].min())
        assert float(row["max_cable_stress"]) == printed(alone["max_cable_stress"].max())
        assert float(row["min_actuation_force"]) == printed(alone["actuation_force"].min())


def test_summary_fields_a_name_for_a_list_and_dotted_entries_for_mappings():
    with tempfile.TemporaryDirectory() as tmp:
        text = """
scene: %s
points: [{analysis.output_interval: 0.001}]
collect:
  summary: %s
"""
        table = study.run_study(write(tmp, text % (IMPACT, "status")), workers=1, progress=False)
        assert list(read_rows(table)[0]) == ["point", "analysis.output_interval", "status", "message"]
        fields = "[peaks.max_normal_force.value, peaks.max_normal_force.t, analysis, duration, name]"
        table = study.run_study(write(tmp, text % (IMPACT, fields), "dotted.yaml"), workers=1, progress=False)
        row = read_rows(table)[0]
        alone = at.run(IMPACT, {"analysis.output_interval": 0.001})
        assert float(row["peaks.max_normal_force.value"]) == alone.summary["peaks"]["max_normal_force"]["value"]
        assert float(row["peaks.max_normal_force.t"]) == alone.summary["peaks"]["max_normal_force"]["t"]
        assert (row["analysis"], row["duration"], row["name"]) == ("dynamic", "0.15", "impact")
        for fields, words in (("[peaks]", "'peaks' is a mapping"), ("peaks.height.value", "no entry 'height'"),
                              ("[final.height]", "collect.final"), ("[time_breakdown.solve]", "name one figure"),
                              ("[no_such_field]", "unknown summary field 'no_such_field'"), ("[1]", "collect.summary")):
            with pytest.raises(study.StudyError) as refused:
                study.read_study(write(tmp, text % (IMPACT, fields), "bad.yaml"))
            assert words in str(refused.value), (fields, str(refused.value))


def test_a_kept_point_is_reused_only_for_what_it_collected():
    with tempfile.TemporaryDirectory() as tmp:
        text = """
scene: %s
points: [{analysis.output_interval: 0.001}]
collect: {peaks: {%s: max}}
"""
        path = write(tmp, text % (IMPACT, "max_normal_force"))
        table = study.run_study(path, workers=1, progress=False)
        assert float(read_rows(table)[0]["max_normal_force"]) > 40e3
        kept = os.path.join(tmp, "peaks", "points")
        (name,) = os.listdir(kept)
        # a record of another format (a peak over the output rows, no time): the point runs again
        with open(os.path.join(kept, name)) as f:
            record = json.load(f)
        old = {"overrides": record["overrides"], "collected": {"status": "converged", "message": "",
                                                               "max_normal_force": 0.0}, "files": {}}
        with open(os.path.join(kept, name), "w") as f:
            json.dump(old, f)
        row = read_rows(study.run_study(path, workers=1, progress=False))[0]
        assert float(row["max_normal_force"]) > 40e3 and float(row["max_normal_force_t"]) > 0.1
        # another peak asked for: the point runs again, and has it
        path = write(tmp, text % (IMPACT, "HA2_tension"))
        row = read_rows(study.run_study(path, workers=1, progress=False))[0]
        assert float(row["max_HA2_tension"]) > 0.0
