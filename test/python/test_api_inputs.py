"""The API's functions given what they do not take (wrong types, NaN, values out of range): each raises
TypeError, ValueError or SceneError with a message that names the argument, never pybind11's list of signatures
or a bare conversion error."""

import os

import pytest

import active_tensegrity as at

SOURCE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PRISM = os.path.join(SOURCE, "config", "scenes", "prism_pinned.yaml")
TOWER = os.path.join(SOURCE, "config", "scenes", "tower.yaml")
NAN, INF = float("nan"), float("inf")


def refused(error, words, call):
    with pytest.raises(error) as raised:
        call()
    message = str(raised.value)
    assert "incompatible function arguments" not in message and "could not convert" not in message, message
    for w in words if isinstance(words, tuple) else (words,):
        assert w in message, (w, message)
    return raised.value


def test_load_and_run():
    for scene in (123, None, b"config/scenes/prism_pinned.yaml", "a\0b", 1.5):
        refused(TypeError, "load: scene", lambda: at.load(scene))
    refused(TypeError, "load: name", lambda: at.load(PRISM, name=1))
    # a non-finite number reaches the loader as YAML's .nan/.inf, which refuses it with the key named
    for value, text in ((NAN, ".nan"), (INF, ".inf"), (-INF, "-.inf")):
        e = refused(at.SceneError, ("solver.dt", text), lambda: at.load(PRISM, {"solver.dt": value}))
        assert e.key == "solver.dt"
    refused(at.SceneError, "solver.dt", lambda: at.load(PRISM, {"solver.dt": [1, 2]}))
    refused(at.SceneError, "solver.dt", lambda: at.load(PRISM, {"solver.dt": "fast"}))
    refused(TypeError, "overrides: a key", lambda: at.load(PRISM, {1: 2}))
    refused(TypeError, "overrides: a key", lambda: at.load(PRISM, {"": 2}))
    refused(TypeError, "overrides: solver.dt", lambda: at.load(PRISM, {"solver.dt": object()}))
    refused(TypeError, "overrides: solver.dt: a mapping's key", lambda: at.load(PRISM, {"solver.dt": {1: 2}}))
    refused(TypeError, "the item 1", lambda: at.load(PRISM, [1]))
    refused(TypeError, "overrides", lambda: at.load(PRISM, 5))
    refused(TypeError, "not one string", lambda: at.load(PRISM, "solver.dt=1"))
    # lists and mappings go as YAML flow text; texts in them quoted
    assert at._value_text([1, "a'b", None, 0.5, {"k": True}]) == '[1, "a\'b", null, 0.5, {"k": true}]'
    refused(ValueError, "nested deeper than 64", lambda: at._value_text(_deep(70)))
    refused(TypeError, "run: extremes", lambda: at.run(PRISM, extremes=1))
    refused(TypeError, "run: extremes", lambda: at.run(PRISM, extremes=[None]))
    refused(ValueError, ("run: extremes: no column 'nope'", "height"), lambda: at.run(PRISM, extremes=["nope"]))
    refused(TypeError, "scene", lambda: at.check(1))
    refused(at.SceneError, "analysis.max_actuation", lambda: at.modal(PRISM, {"analysis.max_actuation": NAN}))


def _deep(levels):
    value = 1
    for _ in range(levels):
        value = [value]
    return value


def test_find_form():
    refused(TypeError, "find_form: tolerance", lambda: at.find_form(PRISM, tolerance="x"))
    refused(ValueError, "find_form: tolerance", lambda: at.find_form(PRISM, tolerance=NAN))
    refused(TypeError, "find_form: max_iterations", lambda: at.find_form(PRISM, max_iterations=1.5))
    refused(ValueError, "find_form: max_iterations", lambda: at.find_form(PRISM, max_iterations=10 ** 30))
    refused(TypeError, "find_form: tension", lambda: at.find_form(PRISM, tension=1))
    refused(TypeError, "find_form: tension: rings", lambda: at.find_form(PRISM, tension={"rings": "x"}))
    refused(ValueError, "find_form: force_density: rings", lambda: at.find_form(PRISM, force_density={"rings": INF}))
    refused(ValueError, "find_form: mode", lambda: at.find_form(PRISM, mode=1))
    refused(ValueError, "find_form: supports", lambda: at.find_form(PRISM, supports=None))
    refused(TypeError, "find_form: scene", lambda: at.find_form(1))


def test_simulation():
    sim = at.Simulation(TOWER)
    refused(ValueError, "advance: steps", lambda: sim.advance(steps=1.5))
    refused(ValueError, "advance: steps", lambda: sim.advance(steps=-1))
    refused(ValueError, "advance: steps", lambda: sim.advance(steps=10 ** 30))
    refused(ValueError, "advance: steps", lambda: sim.advance(steps="3"))
    refused(ValueError, "advance: seconds", lambda: sim.advance(seconds=1e300))
    refused(ValueError, "advance: seconds", lambda: sim.advance(seconds=NAN))
    refused(ValueError, "advance: every", lambda: sim.advance(steps=1, every=NAN))
    refused(TypeError, "advance: callback", lambda: sim.advance(steps=1, callback=1))
    refused(TypeError, "set_targets", lambda: sim.set_targets([1]))
    refused(TypeError, "set_targets: an actuator's name", lambda: sim.set_targets({1: 0.1}))
    refused(ValueError, "set_targets: speed", lambda: sim.set_targets({"pull1": 0.1}, speed=NAN))
    refused(ValueError, "set_targets: accel", lambda: sim.set_targets({"pull1": 0.1}, accel="x"))
    refused(ValueError, "pull1", lambda: sim.set_targets({"pull1": NAN}))
    assert sim.steps == 0 and sim.actuation["pull1"] == 0.0


def test_plan_folding():
    for request, words in (({"target_height": NAN}, "target_height"), ({"max_speeds": [NAN]}, "max_speeds"),
                           ({"time_limit": NAN}, "time_limit"), ({"min_clearance": NAN}, "min_clearance"),
                           ({"sample_dt": INF}, "sample_dt")):
        plan = at.plan_folding(TOWER, **dict({"actuators": ["pull1"], "target_height": 0.5}, **request))
        assert plan["status"] == "invalid_request" and words in plan["message"], (request, plan["message"])
    refused(TypeError, "plan_folding: seed", lambda: at.plan_folding(TOWER, actuators=["pull1"], seed=-1))
    refused(TypeError, "plan_folding: seed", lambda: at.plan_folding(TOWER, actuators=["pull1"], seed=1.5))
    refused(TypeError, "scene", lambda: at.plan_folding(1, actuators=["pull1"]))
