"""active_tensegrity: tensegrity structures with strut contact, from Python.

    import active_tensegrity as at
    scene = at.load("config/scenes/prism_pinned.yaml", {"analysis.steps": 20})
    result = at.run(scene)
    result["height"]          # one column of the CSV that tensegrity_run writes, as a numpy array
    result.nodes              # (output steps, nodes, 3) node positions, m
    result.summary["status"]  # "converged", ...

docs/python.md describes the API.
"""

import os

from active_tensegrity._core import Model, SceneError  # noqa: F401  (re-exported)
from active_tensegrity import _core

__all__ = ["Model", "SceneError", "Result", "load", "run"]


def _override_text(key, value):
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, float):
        text = repr(value)  # the shortest text that reads back as the same double
    else:
        text = str(value)
    return "%s=%s" % (key, text)


def _overrides(overrides):
    if overrides is None:
        return []
    if isinstance(overrides, dict):
        return [_override_text(k, v) for k, v in overrides.items()]
    if isinstance(overrides, str):
        raise TypeError("overrides: a dict {key: value} or a list of 'key=value' texts, not one string")
    return [str(o) for o in overrides]


def load(scene, overrides=None, name="<string>"):
    """Loads and validates a scene: a file's path, or YAML text (any text with a line break).

    overrides: {key: value} or ["key=value", ...], as tensegrity_run --set takes them.
    A refused scene raises SceneError (a ValueError) with the loader's message; its `key` is the key named.
    """
    sets = _overrides(overrides)
    if "\n" in scene and not os.path.exists(scene):
        return _core.load_scene_text(scene, name, sets)
    return _core.load_scene(os.fspath(scene), sets)


class Result:
    """What one run gives, per output step.

    columns, table: tensegrity_run's CSV (names, and an array of steps x columns); result[name] is a column.
    nodes: (steps, nodes, 3) positions, m, in the scene's node order (node_names).
    member_columns, members: tensegrity_run --members (cable tensions, lengths, rest lengths; strut forces).
    contacts: one row per active contact pair and step: step index, strut a, strut b (body indices), point on
      a (x, y, z), point on b, normal, penetration, penetration rate, normal force, friction force on a (x, y, z).
    summary: status, message, warnings, newton_iterations, step_cuts, output_steps, solver_steps, wall_time.
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
    model = scene if isinstance(scene, Model) else load(scene, overrides)
    return Result(model, _core.run(model))
