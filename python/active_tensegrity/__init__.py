"""active_tensegrity: tensegrity structures with strut contact, from Python.

    import active_tensegrity as at
    scene = at.load("config/scenes/prism_pinned.yaml", {"analysis.steps": 20})
    result = at.run(scene)
    result["height"]          # one column of the CSV that tensegrity_run writes, as a numpy array
    result.nodes              # (output steps, nodes, 3) node positions, m
    result.summary["status"]  # "converged", ...

docs/python.md describes the API.
"""

import json
import math
import numbers
import os
import pkgutil

# The package's parts may lie in several folders on sys.path (in a devel space: this source folder, and the
# devel space's with the compiled module and the messages). A process started with a devel space's sys.path
# (a dask or multiprocessing worker) finds this folder first: it looks in the others too.
__path__ = pkgutil.extend_path(__path__, __name__)

from active_tensegrity._core import FormFindingError, Model, SceneError  # noqa: F401  (re-exported)
from active_tensegrity import _core

__all__ = ["FormFindingError", "Model", "SceneError", "Result", "Simulation", "check", "find_form", "load", "modal",
           "plan_folding", "planners", "run"]


def _number(what, value, integer=False, minimum=None, maximum=None, finite=True, wrong_type=TypeError):
    """value as a float (an int when integer), or an error naming `what` and the value: wrong_type for what is
    not a number (a bool is not), ValueError for a number out of range"""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or (integer and not isinstance(value,
                                                                                                    numbers.Integral)):
        raise wrong_type("%s: expected %s, got %r" % (what, "an integer" if integer else "a number", value))
    value = int(value) if integer else float(value)
    if finite and not math.isfinite(value):
        raise ValueError("%s: expected a finite number, got %r" % (what, value))
    if minimum is not None and value < minimum:
        raise ValueError("%s: expected a number >= %s, got %r" % (what, minimum, value))
    if maximum is not None and value > maximum:
        raise ValueError("%s: expected a number <= %s, got %r" % (what, maximum, value))
    return value


def _value_text(value, what="value"):
    """A value as an override takes it (YAML): booleans as YAML writes them, floats in the shortest text that
    reads back as the same double (.nan, .inf, -.inf), None as null, lists and mappings in flow style."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        value = float(value)
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        return repr(value)
    if isinstance(value, (list, tuple, dict)):
        return _flow(value, what)
    raise TypeError("%s: expected a number, text, boolean, list or mapping, got %r (%s)"
                    % (what, value, type(value).__name__))


def _flow(value, what):
    """A list or mapping as YAML flow text (texts quoted), at most 64 levels deep."""
    out, stack = [], [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if depth is None:  # text formed already
            out.append(item)
        elif depth > 64:
            raise ValueError("%s: nested deeper than 64 levels" % what)
        elif isinstance(item, (list, tuple)):
            parts = [("[", None)]
            for i, x in enumerate(item):
                parts += ([(", ", None)] if i else []) + [(x, depth + 1)]
            stack += reversed(parts + [("]", None)])
        elif isinstance(item, dict):
            parts = [("{", None)]
            for i, (k, x) in enumerate(item.items()):
                if not isinstance(k, str):
                    raise TypeError("%s: a mapping's key must be a text, got %r" % (what, k))
                key = json.dumps(k, ensure_ascii=False) + ": "
                parts += ([(", ", None)] if i else []) + [(key, None), (x, depth + 1)]
            stack += reversed(parts + [("}", None)])
        elif isinstance(item, str):
            out.append(json.dumps(item, ensure_ascii=False))
        else:
            out.append(_value_text(item, what))
    return "".join(out)


def _override_text(key, value):
    if not isinstance(key, str) or not key:
        raise TypeError("overrides: a key must be a non-empty text (as analysis.steps), got %r" % (key,))
    return "%s=%s" % (key, _value_text(value, "overrides: " + key))


def _overrides(overrides):
    if overrides is None:
        return []
    if isinstance(overrides, dict):
        return [_override_text(k, v) for k, v in overrides.items()]
    if isinstance(overrides, str):
        raise TypeError("overrides: a dict {key: value} or a list of 'key=value' texts, not one string")
    try:
        texts = list(overrides)
    except TypeError:
        raise TypeError("overrides: a dict {key: value} or a list of 'key=value' texts, got %r" % (overrides,)) \
            from None
    for o in texts:
        if not isinstance(o, str):
            raise TypeError("overrides: a list of 'key=value' texts, got the item %r" % (o,))
    return texts


def _is_text(scene):
    """YAML text rather than a path: a str with a line break that names no file"""
    return isinstance(scene, str) and "\n" in scene and not os.path.exists(scene)


def load(scene, overrides=None, name="<string>"):
    """Loads and validates a scene: a file's path, or YAML text (any text with a line break).

    overrides: {key: value} or ["key=value", ...], as tensegrity_run --set takes them.
    A refused scene raises SceneError (a ValueError) with the loader's message; its `key` is the key named.
    """
    sets = _overrides(overrides)
    if not isinstance(name, str):
        raise TypeError("load: name: expected a text, got %r" % (name,))
    if _is_text(scene):
        return _core.load_scene_text(scene, name, sets)
    return _core.load_scene(_path("load", scene), sets)


def _path(what, scene):
    """scene as a path's text, or TypeError naming what takes it"""
    if isinstance(scene, (str, os.PathLike)):
        path = os.fsdecode(os.fspath(scene))
        if "\0" not in path:
            return path
    raise TypeError("%s: scene: expected a Model, a scene file's path or YAML text, got %r" % (what, scene))


def _model(scene, overrides, extra=()):
    """A loaded Model as given, or what load() takes loaded with `extra` then `overrides` (overrides cannot
    change a Model already loaded: given with one, they are refused)."""
    if isinstance(scene, Model):
        if overrides:
            raise ValueError("overrides apply when a scene is loaded; this one is a loaded Model (pass its path "
                             "or text, or load it with them)")
        return scene
    return load(scene, list(extra) + _overrides(overrides))


def check(scene, overrides=None):
    """The structural diagnostics of a scene's initial state, as tensegrity_run --check prints them: a dict of
    self_stress_states, mechanisms, rigid_body_modes, prestress_stable, the stiffness eigenvalues, slack_cables,
    equilibrium_residual (N), members (every member: struts + tension_members), struts, tension_members (cables
    and springs, the equilibrium matrix's columns) ... (docs/physics.md). A model above the size the check
    handles gives checked=False and a note."""
    return _core.check(_model(scene, overrides))


def find_form(scene, mode="free", tension=None, force_density=None, supports="fixed", struts="uniform",
              strut_lengths="free", tolerance=1e-12, max_iterations=100):
    """Form-finding, as tensegrity_formfind (docs/form_finding.md): the self-equilibrated form of a scene's
    topology. scene: a path or YAML text. mode: "free" (the geometry is found with each family's tension (N) or
    force density (N/m) held) or "prestress" (the geometry kept, its self-stress fitted to the tensions);
    supports "fixed" or "react"; struts "uniform" or "free"; strut_lengths "free" or "keep".

    Returns a dict: scene (the written scene, YAML text: load() takes it), node_names, positions (nodes x 3, m),
    members (name, family, strut, tension, length), iterations, residual (N), max_move (m), scale,
    self_stress_states, notes, changes (the parameters of the scene's layout the form changed, one text each,
    tensegrity_formfind's warnings), check (the written scene's own check). A refused scene raises SceneError;
    a form that cannot be found raises FormFindingError with the reason."""
    def choice(what, value, a, b):
        if not isinstance(value, str) or value not in (a, b):
            raise ValueError("find_form: %s must be %r or %r, got %r" % (what, a, b, value))
        return value == a

    def family_values(what, values):
        if values is None:
            return {}
        if not isinstance(values, dict):
            raise TypeError("find_form: %s: expected {family: value}, got %r" % (what, values))
        out = {}
        for family, value in values.items():
            if not isinstance(family, str):
                raise TypeError("find_form: %s: a family's name must be a text, got %r" % (what, family))
            out[family] = _number("find_form: %s: %s" % (what, family), value)
        return out
    if not isinstance(mode, str):
        raise ValueError("find_form: mode must be 'free' or 'prestress', got %r" % (mode,))
    if _is_text(scene):
        text, name = scene, "<string>"
    else:
        name = _path("find_form", scene)
        with open(name) as f:
            text = f.read()
    return _core.find_form(text, name, mode, family_values("tension", tension),
                           family_values("force_density", force_density),
                           not choice("supports", supports, "fixed", "react"),
                           choice("struts", struts, "uniform", "free"),
                           not choice("strut_lengths", strut_lengths, "free", "keep"),
                           _number("find_form: tolerance", tolerance),
                           _number("find_form: max_iterations", max_iterations, integer=True, maximum=10000))


def planners():
    """The names of the OMPL planners plan_folding takes."""
    return _core.planners()


def plan_folding(scene, **request):
    """The collision-aware folding planner (docs/planning.md). scene: a Model, what load() takes (the plan starts
    from the scene's start), or a Simulation: planned as the ROS node plans, from its live state under the
    actuation in force. The trajectory starts at the chosen actuators' values and rates; when they move, it first
    brakes them at max_accelerations (stop_duration s), and the path starts at the equilibrium nearest to where
    they stop. The dynamic verification simulates the trajectory from the live state itself (positions,
    velocities, contact memory), the other actuators following their commands: Simulation.follow(plan) then runs
    it.

    request: the planner's fields by name: actuators (names), target_height (m) or target_values (one per
    actuator), min_clearance (m), allow_contact, max_contact_force (N), max_cable_stress (Pa), max_speeds,
    max_accelerations, planner, time_limit (s), seed, continuation_step (m), range, sample_dt (s),
    reachability_check, verify_dynamics, find_speed_limit, max_bending_stress (Pa), settle_time (s),
    blend_tolerance (m). An unknown name raises ValueError; a request the planner refuses comes back with
    status "invalid_request" and the reason.

    Returns a dict: status, message, names; waypoints (points x actuators); the trajectory as times (s from the
    start) and positions, velocities, accelerations (times x actuators); duration, rest_to_rest_duration (both
    with stop_duration), stop_duration, min_gap, peak_contact_force, final_height, equilibrium_solves,
    planning_time, stopped_by_time_limit, cancelled; with verify_dynamics: dynamics_verified,
    dynamics_within_limits, dynamic_peak_contact_force, dynamic_peak_bending_stress, dynamic_min_gap,
    settle_duration, time_scale, dynamic_runs."""
    target = scene._sim if isinstance(scene, Simulation) else _model(scene, None)
    return _core.plan_folding(target, **request)


def modal(scene, overrides=None):
    """The natural modes of a scene about its equilibrium at analysis.max_actuation (analysis.type is set to
    modal; analysis.modes gives how many, the lowest). A dict: frequency_hz, omega (rad/s), eigenvalue (1/s^2)
    per mode (ascending; negative where the equilibrium is unstable along the mode), shapes (modes x nodes x 3,
    node displacements scaled to a largest of 1), free_coordinates, structure (check() of the equilibrium),
    status, message, warnings, wall_time (s)."""
    return _core.modal(_model(scene, overrides, ["analysis.type=modal"]))


class Result:
    """What one run gives, per output step.

    columns, table: tensegrity_run's CSV (names, and an array of steps x columns); result[name] is a column.
    nodes: (steps, nodes, 3) positions, m, in the scene's node order (node_names).
    member_columns, members: tensegrity_run --members (cable tensions, lengths, rest lengths; strut forces).
    contacts: one row per active contact and step: step index, strut a, strut b (body indices; b is -1 for the
      ground), point on a (x, y, z), point on b, normal, penetration, penetration rate, normal force, friction
      force on a (x, y, z).
    summary: tensegrity_run's summary as a dict (but its scene): name, analysis, status, message, output_steps,
      solver_steps, newton_iterations, step_cuts, wall_time, (dynamic runs) duration, real_time_factor,
      adaptive_steps, energy (the energy account, J: start and end {kinetic, elastic, gravity, total},
      actuator_work, damping_dissipation, contact_dissipation, numerical_dissipation, largest_step_gain
      {"value", "t"}, gaining_steps, contact_loss_steps, contact_unresolved), warnings, time_breakdown, final
      ({column: value} of the run's last state), and
      peaks: {column: {"value", "t"}}, the largest magnitude over the start and every step (not only the output
      steps) of actuation_force, max_normal_force, max_friction_force, max_strut_bending_stress, max_cable_stress.
    extremes: {column: {"max": {"value", "t"}, "min": {"value", "t"}, "states": n}} of the columns run() was
      asked to track: the largest and smallest value over the start and every time or load step, and the time
      (or path parameter) of the first state that reached it; NaN when the column is NaN at any state.
    """

    CONTACT_COLUMNS = ("step", "strut_a", "strut_b", "point_a_x", "point_a_y", "point_a_z", "point_b_x",
                       "point_b_y", "point_b_z", "normal_x", "normal_y", "normal_z", "penetration",
                       "penetration_rate", "normal_force", "friction_x", "friction_y", "friction_z")

    def __init__(self, model, raw):
        self.columns = list(raw["columns"])
        self.table = raw["table"]
        self.nodes = raw["nodes"]
        self.node_names = model.nodes
        self.member_columns = list(raw["member_columns"])
        self.members = raw["members"]
        self.contacts = raw["contacts"]
        self.summary = dict(raw["summary"])
        self.extremes = dict(raw["extremes"])

    def __getitem__(self, column):
        if column in self.columns:
            return self.table[:, self.columns.index(column)]
        if column in self.member_columns:
            return self.members[:, self.member_columns.index(column)]
        raise KeyError("%r: not a column (columns: %s; members: %s)"
                       % (column, ", ".join(self.columns), ", ".join(self.member_columns)))

    @property
    def ok(self):
        return self.summary["status"] == "converged"


def run(scene, overrides=None, extremes=None):
    """Runs a scene's analysis (static path or dynamic run); returns a Result.

    scene: a Model from load(), or what load() takes (then overrides apply). extremes: columns (of the CSV or
    the members' table; one name or a list) whose largest and smallest values over every step the run tracks
    (Result.extremes). The interpreter's lock is released while the analysis runs: other Python threads go on.
    """
    model = _model(scene, overrides)
    if extremes is None:
        extremes = []
    elif isinstance(extremes, str):
        extremes = [extremes]
    elif not isinstance(extremes, (list, tuple)) or not all(isinstance(c, str) for c in extremes):
        raise TypeError("run: extremes: expected a column's name or a list of them, got %r" % (extremes,))
    return Result(model, _core.run(model, list(extremes)))


class Simulation:
    """A dynamic simulation stepped from Python, as the ROS node steps it: fixed steps of the scene's
    solver.dt from the scene's initial state; actuation commands ramp each actuator to a target under speed and
    acceleration limits without a jump in value or rate.

        sim = at.Simulation("config/scenes/tower.yaml")
        sim.set_targets({"pull1": 0.3})
        sim.advance(seconds=1.0, callback=lambda s: print(s.t, s.height), every=0.01)

    State (read at any time): t (s), steps, height (m), actuation ({name: value}), row (the CSV row as a dict),
    nodes (array nodes x 3, m). plan_folding(sim, ...) plans from the live state; follow(plan) runs the plan.
    A step that fails raises RuntimeError with the solver's status; the simulation keeps its last good state.
    """

    def __init__(self, scene, overrides=None):
        self.model = _model(scene, overrides)
        self._sim = _core.Simulation(self.model)

    def __getattr__(self, name):
        if name in ("t", "steps", "dt", "height", "actuation", "row", "nodes"):
            return getattr(self._sim, name)
        raise AttributeError(name)

    def follow(self, plan):
        """Runs a trajectory from now, as the node's ~follow_trajectory: plan is plan_folding's answer (or a dict
        of names, times (s from now), positions and optionally velocities, times x actuators). The named actuators
        follow it, the others their commands; a trajectory the controller refuses (times not increasing, a value
        out of range, an unknown name) raises ValueError and changes nothing."""
        if not isinstance(plan, dict) or not all(k in plan for k in ("names", "times", "positions")):
            raise TypeError("follow: expected a plan (a dict of names, times, positions, velocities), got %r"
                            % (plan,))

        def rows(values):
            return [[float(x) for x in row] for row in values]
        self._sim.follow(list(plan["names"]), [float(t) for t in plan["times"]], rows(plan["positions"]),
                         rows(plan.get("velocities", [])))

    def set_targets(self, targets, speed=0.0, accel=0.0):
        """Ramps the named actuators to their targets ({name: value}, m) from now, at most `speed` (m/s) and
        `accel` (m/s^2); 0 takes the node's defaults (the scene's actuation.speed, else 0.1 m/s). An unknown
        name, a target out of the actuator's range, a NaN or a speed <= 0 raises ValueError and changes
        nothing."""
        if not isinstance(targets, dict):
            raise TypeError("set_targets: expected {actuator: target (m)}, got %r" % (targets,))
        names = list(targets)
        values = []
        for n in names:
            if not isinstance(n, str):
                raise TypeError("set_targets: an actuator's name must be a text, got %r" % (n,))
            values.append(_number("set_targets: " + n, targets[n], finite=False, wrong_type=ValueError))
        self._sim.set_targets(names, values, [], [],
                              _number("set_targets: speed", speed, minimum=0.0, wrong_type=ValueError),
                              _number("set_targets: accel", accel, minimum=0.0, wrong_type=ValueError))

    def advance(self, seconds=None, steps=None, callback=None, every=None):
        """Advances by `seconds` (rounded to whole steps) or `steps`. callback(sim), when given, is called every
        `every` seconds of simulated time (default: every step); it may read the state and set targets, and
        ends the advance early by returning False. Returns the number of steps taken."""
        if (seconds is None) == (steps is None):
            raise ValueError("advance: give seconds or steps")
        if seconds is not None:
            seconds = _number("advance: seconds", seconds, minimum=0.0, wrong_type=ValueError)
        if steps is not None:
            steps = _number("advance: steps", steps, integer=True, minimum=0, maximum=2 ** 62, wrong_type=ValueError)
        if every is not None:
            every = _number("advance: every", every, minimum=0.0, wrong_type=ValueError)
        if callback is not None and not callable(callback):
            raise TypeError("advance: callback: expected a function of the simulation, got %r" % (callback,))
        dt = self._sim.dt
        n = steps if steps is not None else int(round(seconds / dt))
        k = 1 if every is None else max(1, min(2 ** 62, int(round(every / dt))))
        if n > 2 ** 62:
            raise ValueError("advance: seconds: %r s are more than 2^62 steps of %r s" % (seconds, dt))
        if callback is None:
            return self._sim.advance(n)
        return self._sim.advance(n, lambda _: callback(self), k)
