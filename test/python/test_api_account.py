"""The Python API against tensegrity_run and the planner: the energy account of a dynamic run, the structure
report's member counts, form-finding's changes, and plan_folding from a moving Simulation.

Run by scripts/test through catkin (pytest, with the devel space's environment)."""

import math
import os
import subprocess
import tempfile

import numpy as np
import pytest
import yaml

import active_tensegrity as at

SOURCE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = os.path.join(SOURCE, "config", "scenes")
# the package's module lives in <space>/lib/python3/dist-packages/active_tensegrity; the tools in
# <space>/lib/active_tensegrity
SPACE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(at._core.__file__)))))


def tool(name):
    return os.path.join(SPACE, "lib", "active_tensegrity", name)


def cli_summary(scene, sets):
    """tensegrity_run's summary (--summary) of scene with --set texts, read as YAML"""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "summary.yaml")
        command = [tool("tensegrity_run"), scene, "--out", os.devnull, "--summary", path]
        for s in sets:
            command += ["--set", s]
        done = subprocess.run(command, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        with open(path) as f:
            return yaml.safe_load(f)


def printed(value):
    """a number as tensegrity_run prints it (10 significant digits), read back"""
    return float("%.10g" % value)


def assert_same_as_printed(ours, theirs, where=""):
    """ours (dicts, numbers) equal to theirs (the YAML read back), key for key, at the printed digits"""
    if isinstance(ours, dict):
        assert isinstance(theirs, dict) and set(ours) == set(theirs), (where, ours, theirs)
        for key in ours:
            assert_same_as_printed(ours[key], theirs[key], where + "." + key)
    elif isinstance(ours, float):
        assert printed(ours) == theirs, (where, ours, theirs)
    else:
        assert ours == theirs, (where, ours, theirs)


ENERGY_KEYS = {"start", "end", "actuator_work", "damping_dissipation", "contact_dissipation",
               "numerical_dissipation", "largest_step_gain", "gaining_steps", "contact_loss_steps",
               "contact_unresolved"}


def assert_account_closes(e):
    """start + actuator_work - damping - contact - numerical == end, to 1e-9 of the largest term"""
    for point in (e["start"], e["end"]):
        assert set(point) == {"kinetic", "elastic", "gravity", "total"}
        assert point["total"] == pytest.approx(point["kinetic"] + point["elastic"] + point["gravity"],
                                               rel=1e-12, abs=1e-12)
    terms = [e["start"]["total"], e["actuator_work"], -e["damping_dissipation"], -e["contact_dissipation"],
             -e["numerical_dissipation"]]
    scale = max(abs(x) for x in terms + [e["end"]["total"], e["start"]["kinetic"] + e["start"]["elastic"]])
    assert abs(sum(terms) - e["end"]["total"]) <= 1e-9 * scale, (terms, e["end"])


@pytest.mark.parametrize("scene,sets", [
    ("prism_released.yaml", []),
    ("prism_released.yaml", ["solver.adaptive=true", "analysis.duration=0.3"]),
    # actuator work and contact: the tower folded at 2 m/s
    ("tower.yaml", ["analysis.type=dynamic", "actuation.speed=2.0", "analysis.duration=1.0"]),
])
def test_the_energy_account_closes_and_equals_the_command_line(scene, sets):
    path = os.path.join(SCENES, scene)
    result = at.run(path, sets)
    assert result.ok, result.summary["message"]
    e = result.summary["energy"]
    assert set(e) == ENERGY_KEYS
    assert set(e["largest_step_gain"]) == {"value", "t"}
    assert_account_closes(e)
    # the same run's account as tensegrity_run writes it, at its printed digits; and the rest of the summary
    # (the peaks with the start counted) but what differs from run to run
    theirs = cli_summary(path, sets)
    assert_same_as_printed(e, theirs["energy"], "energy")
    varying = {"scene", "wall_time", "real_time_factor", "time_breakdown"}
    assert set(result.summary) - varying == set(theirs) - varying
    for key in set(theirs) - varying:
        assert_same_as_printed(result.summary[key], theirs[key], key)
    # the end is the run's last state: its kinetic energy moves with it
    assert e["end"]["kinetic"] > 0.0
    if "solver.adaptive=true" in sets:
        a = result.summary["adaptive_steps"]
        assert "rejected_energy" in a and a["rejected_energy"] >= 0
        assert a["rejected_energy"] == theirs["adaptive_steps"]["rejected_energy"]
    else:
        assert "adaptive_steps" not in result.summary
    if scene == "tower.yaml":
        assert e["actuator_work"] > 0.0


def test_a_static_run_has_no_energy_account():
    result = at.run(os.path.join(SCENES, "prism_pinned.yaml"), {"analysis.steps": 5})
    assert result.ok and "energy" not in result.summary
    assert "energy" not in cli_summary(os.path.join(SCENES, "prism_pinned.yaml"), ["analysis.steps=5"])


@pytest.mark.parametrize("name", ["prism_pinned.yaml", "prism_pinned_sliding.yaml", "tower.yaml"])
def test_the_structure_report_counts_struts_and_tension_members(name):
    scene = os.path.join(SCENES, name)
    done = subprocess.run([tool("tensegrity_run"), scene, "--check"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    theirs = yaml.safe_load(done.stdout)
    ours = at.check(scene)
    model = at.load(scene)
    for key in ("members", "struts", "tension_members"):
        assert ours[key] == theirs[key], key
    assert ours["members"] == ours["struts"] + ours["tension_members"]
    assert ours["struts"] == sum(1 for c in model.member_columns if c.endswith("_force")) > 0
    assert ours["tension_members"] > 0


def test_the_modal_structure_report_counts_struts_and_tension_members():
    scene = os.path.join(SCENES, "prism_pinned.yaml")
    s = at.modal(scene)["structure"]
    c = at.check(scene)
    assert s["struts"] == c["struts"] == 3
    assert s["members"] == s["struts"] + s["tension_members"]


PULLS = ["pull1", "pull2", "pull3", "pull4"]


def test_plan_folding_from_a_moving_simulation_verifies_what_the_simulation_then_does():
    # The tower 2.5 s into a pull of its four cables at 0.3 m/s towards 1.2 m: struts and actuators move. Planned
    # from there, the trajectory starts at the actuators' values and rates and brakes them (1 m/s^2, 0.3 s) before
    # the path; the verification simulates it from the live state under the simulation's own commands. The
    # simulation then running the plan gives the verified peak.
    sim = at.Simulation(os.path.join(SCENES, "tower.yaml"), {"solver.dt": 1e-3})
    sim.set_targets({n: 1.2 for n in PULLS}, speed=0.3, accel=3.0)
    sim.advance(seconds=2.5)
    moving = sim.actuation
    assert all(moving[n] == pytest.approx(0.3 * 2.45, abs=1e-9) for n in PULLS)  # cruising at 0.3 m/s
    t0, steps0, height0 = sim.t, sim.steps, sim.height
    plan = at.plan_folding(sim, actuators=PULLS, target_height=0.5, allow_contact=True, max_contact_force=400.0,
                           max_speeds=[0.2], max_accelerations=[1.0], verify_dynamics=True, settle_time=0.5,
                           time_limit=60.0)
    assert plan["status"] == "exact_solution", plan["message"]
    assert plan["dynamics_verified"], plan["message"]
    # planning reads the simulation, it does not move it
    assert (sim.t, sim.steps, sim.height) == (t0, steps0, height0)
    # the trajectory starts where the actuators are, at their rates, and stops them 45 mm further in
    assert plan["stop_duration"] == pytest.approx(0.3, abs=1e-12)
    assert plan["times"][0] == 0.0
    np.testing.assert_array_equal(plan["positions"][0], [moving[n] for n in PULLS])
    np.testing.assert_allclose(plan["velocities"][0], [0.3] * 4, atol=1e-12)
    np.testing.assert_allclose(plan["waypoints"][0], [moving[n] + 0.045 for n in PULLS], atol=1e-9)
    assert plan["duration"] == pytest.approx(plan["times"][-1], abs=1e-12)
    assert plan["final_height"] <= 0.5
    for key in ("cancelled", "dynamic_runs", "rest_to_rest_duration"):
        assert key in plan

    # the simulation runs the plan from the same state, over the verified span: its largest contact force
    sim.follow(plan)
    peak = {"force": sim.row["max_normal_force"], "bending": sim.row["max_strut_bending_stress"],
            "gap": sim.row["min_gap"]}

    def record(s):
        row = s.row
        peak["force"] = max(peak["force"], row["max_normal_force"])
        peak["bending"] = max(peak["bending"], row["max_strut_bending_stress"])
        peak["gap"] = min(peak["gap"], row["min_gap"])
    span = plan["duration"] + plan["settle_duration"]
    sim.advance(seconds=span, callback=record)
    verified = plan["dynamic_peak_contact_force"]
    print("[ measured ] verified peak %.4f N, the simulation's %.4f N (relative %.2e); bending %.6g / %.6g Pa; "
          "gap %.6g / %.6g m; trajectory %.2f s"
          % (verified, peak["force"], abs(verified - peak["force"]) / peak["force"],
             plan["dynamic_peak_bending_stress"], peak["bending"], plan["dynamic_min_gap"], peak["gap"],
             plan["duration"]))
    # the moving start presses the struts far beyond the path's quasi-static force (810 N against 171 N); the
    # verification's solver starts from the state, the simulation's goes on: 8e-7 apart (relative), 1e-4 allowed
    assert peak["force"] > 2.0 * plan["peak_contact_force"]
    assert plan["dynamic_peak_contact_force"] == pytest.approx(peak["force"], rel=1e-4)
    assert plan["dynamic_peak_bending_stress"] == pytest.approx(peak["bending"], rel=1e-4)
    assert plan["dynamic_min_gap"] == pytest.approx(peak["gap"], rel=1e-4, abs=1e-7)
    np.testing.assert_allclose([sim.actuation[n] for n in PULLS], plan["positions"][-1], atol=1e-9)


def test_follow_refuses_what_the_controller_refuses():
    sim = at.Simulation(os.path.join(SCENES, "tower.yaml"))
    with pytest.raises(ValueError) as refused:
        sim.follow({"names": ["no_such_actuator"], "times": [0.0, 1.0], "positions": [[0.0], [0.1]]})
    assert "no_such_actuator" in str(refused.value)
    with pytest.raises(ValueError):
        sim.follow({"names": ["pull1"], "times": [0.0, 0.0], "positions": [[0.0], [0.1]]})
    with pytest.raises(TypeError):
        sim.follow([0.0, 1.0])
    assert sim.advance(steps=2) == 2  # it goes on


def test_a_study_collects_the_energy_account_by_dotted_names():
    import csv
    from active_tensegrity import study
    scene = os.path.join(SCENES, "prism_released.yaml")
    fields = ["energy.start.total", "energy.end.kinetic", "energy.numerical_dissipation",
              "energy.largest_step_gain.t", "energy.gaining_steps", "adaptive_steps.rejected_energy"]
    with tempfile.TemporaryDirectory() as tmp:
        text = "scene: %s\npoints: [{analysis.duration: 0.2}]\nset: {solver.adaptive: true}\ncollect: {summary: [%s]}\n"
        path = os.path.join(tmp, "energy.yaml")
        with open(path, "w") as f:
            f.write(text % (scene, ", ".join(fields)))
        saved = os.path.join(tmp, "saved.yaml")
        with open(saved, "w") as f:
            f.write(text % (scene, ", ".join(fields)) + "save: {name: released, files: [summary]}\n")
        rows = []
        for p in (path, saved):
            with open(study.run_study(p, workers=1, progress=False)) as f:
                rows.append(list(csv.DictReader(f))[0])
        alone = at.run(scene, {"analysis.duration": 0.2, "solver.adaptive": True}).summary
        for field in fields:
            value = alone
            for part in field.split("."):
                value = value[part]
            assert float(rows[0][field]) == value, field  # in-process: the number itself
            assert float(rows[1][field]) == printed(value), field  # saved: the summary file's digits
        for bad, words in (("energy.start", "name one figure, as energy.start.kinetic"),
                           ("energy.actuator_work.value", "name one figure"), ("energy.heat", "no entry 'heat'")):
            with open(path, "w") as f:
                f.write(text % (scene, bad))
            with pytest.raises(study.StudyError) as refused:
                study.read_study(path)
            assert words in str(refused.value), (bad, str(refused.value))
