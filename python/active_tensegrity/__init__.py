"""active_tensegrity: tensegrity structures with strut contact, from Python.

    import active_tensegrity as at
    scene = at.load("config/scenes/prism_pinned.yaml", {"analysis.steps": 20})
    result = at.run(scene)
    result["height"]          # one column of the CSV that tensegrity_run writes, as a numpy array
    result.nodes              # (output steps, nodes, 3) node positions, m
    result.summary["status"]  # "converged", ...

docs/python.md describes the API.
"""

import math
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


def _value_text(value):
    """A value as an override takes it: booleans as YAML writes them, floats in the shortest text that reads back
    as the same double."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def _override_text(key, value):
    return "%s=%s" % (key, _value_text(value))


def _overrides(overrides):
    if overrides is None:
        return []
    if isinstance(overrides, dict):
        return [_override_text(k, v) for k, v in overrides.items()]
    if isinstance(overrides, str):
        raise TypeError("overrides: a dict {key: value} or a list of 'key=value' texts, not one string")
    return [str(o) for o in overrides]


def _is_text(scene):
    """YAML text rather than a path: a str with a line break that names no file"""
    return isinstance(scene, str) and "\n" in scene and not os.path.exists(scene)


def load(scene, overrides=None, name="<string>"):
    """Loads and validates a scene: a file's path, or YAML text (any text with a line break).

    overrides: {key: value} or ["key=value", ...], as tensegrity_run --set takes them.
    A refused scene raises SceneError (a ValueError) with the loader's message; its `key` is the key named.
    """
    sets = _overrides(overrides)
    if _is_text(scene):
        return _core.load_scene_text(scene, name, sets)
    return _core.load_scene(os.fspath(scene), sets)


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
    equilibrium_residual (N) ... (docs/physics.md). A model above the size the check handles gives
    checked=False and a note."""
    return _core.check(_model(scene, overrides))


def find_form(scene, mode="free", tension=None, force_density=None, supports="fixed", struts="uniform",
              strut_lengths="free", tolerance=1e-12, max_iterations=100):
    """Form-finding, as tensegrity_formfind (docs/form_finding.md): the self-equilibrated form of a scene's
    topology. scene: a path or YAML text. mode: "free" (the geometry is found with each family's tension (N) or
    force density (N/m) held) or "prestress" (the geometry kept, its self-stress fitted to the tensions);
    supports "fixed" or "react"; struts "uniform" or "free"; strut_lengths "free" or "keep".

    Returns a dict: scene (the written scene, YAML text: load() takes it), node_names, positions (nodes x 3, m),
    members (name, family, strut, tension, length), iterations, residual (N), max_move (m), scale,
    self_stress_states, notes, check (the written scene's own check). A refused scene raises SceneError; a form
    that cannot be found raises FormFindingError with the reason."""
    def choice(what, value, a, b):
        if value not in (a, b):
            raise ValueError("find_form: %s must be %r or %r, got %r" % (what, a, b, value))
        return value == a
    if _is_text(scene):
        text, name = scene, "<string>"
    else:
        with open(os.fspath(scene)) as f:
            text, name = f.read(), os.fspath(scene)
    return _core.find_form(text, name, mode, dict(tension or {}), dict(force_density or {}),
                           not choice("supports", supports, "fixed", "react"),
                           choice("struts", struts, "uniform", "free"),
                           not choice("strut_lengths", strut_lengths, "free", "keep"),
                           float(tolerance), int(max_iterations))


def planners():
    """The names of the OMPL planners plan_folding takes."""
    return _core.planners()


def plan_folding(scene, **request):
    """The collision-aware folding planner (docs/planning.md). scene: a Model, what load() takes, or a
    Simulation (the plan starts from its live state's nearest equilibrium; else from the scene's start).

    request: the planner's fields by name: actuators (names), target_height (m) or target_values (one per
    actuator), min_clearance (m), allow_contact, max_contact_force (N), max_cable_stress (Pa), max_speeds,
    max_accelerations, planner, time_limit (s), seed, continuation_step (m), range, sample_dt (s),
    reachability_check, verify_dynamics, find_speed_limit, max_bending_stress (Pa), settle_time (s),
    blend_tolerance (m). An unknown name raises ValueError; a request the planner refuses comes back with
    status "invalid_request" and the reason.

    Returns a dict: status, message, names; waypoints (points x actuators); the trajectory as times (s) and
    positions, velocities, accelerations (times x actuators); duration, rest_to_rest_duration, min_gap,
    peak_contact_force, final_height, equilibrium_solves, planning_time, stopped_by_time_limit; with
    verify_dynamics: dynamics_verified, dynamics_within_limits, dynamic_peak_contact_force,
    dynamic_peak_bending_stress, dynamic_min_gap, settle_duration, time_scale."""
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
    summary: status, message, warnings, newton_iterations, step_cuts, output_steps, solver_steps, wall_time, and
      peaks: {column: {"value", "t"}}, the largest magnitude over every step (not only the output steps) of
      actuation_force, max_normal_force, max_friction_force, max_strut_bending_stress, max_cable_stress.
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


def run(scene, overrides=None):
    """Runs a scene's analysis (static path or dynamic run); returns a Result.

    scene: a Model from load(), or what load() takes (then overrides apply). The interpreter's lock is
    released while the analysis runs: other Python threads go on.
    """
    model = _model(scene, overrides)
    return Result(model, _core.run(model))


class Simulation:
    """A dynamic simulation stepped from Python, as the ROS node steps it: fixed steps of the scene's
    solver.dt from the scene's initial state; actuation commands ramp each actuator to a target under speed and
    acceleration limits without a jump in value or rate.

        sim = at.Simulation("config/scenes/tower.yaml")
        sim.set_targets({"pull1": 0.3})
        sim.advance(seconds=1.0, callback=lambda s: print(s.t, s.height), every=0.01)

    State (read at any time): t (s), steps, height (m), actuation ({name: value}), row (the CSV row as a dict),
    nodes (array nodes x 3, m). A step that fails raises RuntimeError with the solver's status; the simulation
    keeps its last good state.
    """

    def __init__(self, scene, overrides=None):
        self.model = _model(scene, overrides)
        self._sim = _core.Simulation(self.model)

    def __getattr__(self, name):
        if name in ("t", "steps", "dt", "height", "actuation", "row", "nodes"):
            return getattr(self._sim, name)
        raise AttributeError(name)

    def set_targets(self, targets, speed=0.0, accel=0.0):
        """Ramps the named actuators to their targets ({name: value}, m) from now, at most `speed` (m/s) and
        `accel` (m/s^2); 0 takes the node's defaults (the scene's actuation.speed, else 0.1 m/s). An unknown
        name, a target out of the actuator's range, a NaN or a speed <= 0 raises ValueError and changes
        nothing."""
        names = list(targets)
        values = []
        for n in names:
            try:
                values.append(float(targets[n]))
            except (TypeError, ValueError):
                raise ValueError("set_targets: %s: expected a number (m), got %r" % (n, targets[n])) from None
        self._sim.set_targets(names, values, [], [], float(speed), float(accel))

    def advance(self, seconds=None, steps=None, callback=None, every=None):
        """Advances by `seconds` (rounded to whole steps) or `steps`. callback(sim), when given, is called every
        `every` seconds of simulated time (default: every step); it may read the state and set targets, and
        ends the advance early by returning False. Returns the number of steps taken."""
        if (seconds is None) == (steps is None):
            raise ValueError("advance: give seconds or steps")
        for what, value in (("seconds", seconds), ("every", every)):
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError("advance: %s must be a finite number >= 0, got %r" % (what, value))
        dt = self._sim.dt
        n = steps if steps is not None else int(round(seconds / dt))
        k = 1 if every is None else max(1, int(round(every / dt)))
        if callback is None:
            return self._sim.advance(n)
        return self._sim.advance(n, lambda _: callback(self), k)
