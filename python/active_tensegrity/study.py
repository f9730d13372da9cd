"""Parameter studies on dask.distributed: one scene, many overrides, one table of results.

    python3 -m active_tensegrity.study STUDY.yaml [--scheduler tcp://HOST:8786] [--workers N] [--out DIR]
                                       [--set KEY=VALUE]... [--check] [--no-progress]

A study file (YAML):

    scene: ../config/scenes/prism_pinned.yaml   # relative to the study file
    set: {analysis.steps: 20}                   # overrides every point gets
    grid:                                       # every combination of these values ...
      analysis.max_actuation: [0.0005, 0.001, 0.002]
      struts.radius: [0.01, 0.02]
    points:                                     # ... and/or these points (overrides each)
      - {analysis.max_actuation: 0.0015}
    collect:
      summary: [status, message, newton_iterations, wall_time]   # summary fields (default: status, message)
      peaks: {max_normal_force: max, height: min}                # a column's largest or smallest value over
                                                                 # every step, and when
      final: [height, actuation]                                 # a column's value in the last output row
    save:                                       # optional: each point's files, as tensegrity_run writes them
      name: "r{struts.radius}_h{analysis.max_actuation}"   # their stem; {key}: the point's value of key
      files: [table, summary, contacts]         # <name>.csv, <name>.yaml, <name>_contacts.csv (also: nodes, members)
    plots:                                      # optional: figures of results.csv (matplotlib)
      - {x: analysis.max_actuation, y: [min_height], by: struts.radius, file: height.png}

Without --scheduler the points run on a LocalCluster of --workers processes (default: the machine's cores);
with it, on the cluster of that scheduler (dask-scheduler, and dask-worker on each machine, every worker with
this package installed and its environment sourced). The scene travels as text: workers need no copy of it.

Results go to --out (default: the study file's name without .yaml, beside it): points/<id>.json per point
(its overrides and what was collected), kept across runs, so a re-run computes only the points not yet done
(or collected otherwise); results.csv, one row per point in the study's order; the saved files and the plots.
A point that fails (a refused scene, a run that stops) is recorded with its status and message; the study goes
on. --set KEY=VALUE (repeatable) overrides KEY in every point, over the study file's values. --check reads the
study file and prints its points and columns, running nothing. Exit status: 0, 1 when the study cannot be run
(one line on stderr names the key and the value), 2 for arguments it does not take. docs/python.md describes it.
"""

import argparse
import csv
import datetime
import hashlib
import itertools
import json
import math
import os
import re
import reprlib
import shutil
import subprocess
import sys
import tempfile

import yaml

DEFAULT_SUMMARY = ["status", "message"]
# the files a point can save: the tensegrity_run option that writes it and its file name after the stem
SAVED_FILES = {"table": ("--out", ".csv"), "summary": ("--summary", ".yaml"),
               "contacts": ("--contacts", "_contacts.csv"), "nodes": ("--nodes", "_nodes.csv"),
               "members": ("--members", "_members.csv")}
STUDY_KEYS = ["scene", "set", "grid", "points", "collect", "save", "plots"]
# a run's summary (tensegrity_run's, as run() gives it): the fields collect.summary takes, and the mappings it
# takes an entry of by a dotted name (peaks.max_normal_force.value): each mapping's entries, then the entries'
# fields ([] for a number; a dict {entry: fields} where they differ, an entry not in it a number)
SUMMARY_FIELDS = ["name", "scene", "analysis", "status", "message", "output_steps", "solver_steps",
                  "newton_iterations", "step_cuts", "wall_time", "duration", "duration_note", "real_time_factor",
                  "warnings"]
SUMMARY_MAPPINGS = {
    "peaks": (["actuation_force", "max_normal_force", "max_friction_force", "max_strut_bending_stress",
               "max_cable_stress"], ["value", "t"]),
    "adaptive_steps": (["accepted", "rejected_error", "rejected_onset", "rejected_solver", "rejected_energy",
                        "at_min_step", "smallest", "largest"], []),
    "energy": (["start", "end", "actuator_work", "damping_dissipation", "contact_dissipation", "numerical_dissipation",
                "largest_step_gain", "gaining_steps", "contact_loss_steps", "contact_unresolved"],
               {"start": ["kinetic", "elastic", "gravity", "total"], "end": ["kinetic", "elastic", "gravity", "total"],
                "largest_step_gain": ["value", "t"]}),
    "time_breakdown": (["forces", "contact", "constraints", "factorization", "solve", "solver_other", "callbacks",
                        "rest"], ["seconds", "share"]),
}
# what a kept point's record must say to be reused: its format, and the collect it was collected for
RECORD_FORMAT = 2
# a study file's limits: bytes, nesting, values (an alias counts at each use), points
MAX_BYTES = 16 << 20
MAX_DEPTH = 64
MAX_VALUES = 1000000
MAX_POINTS = 100000
MAX_WORKERS = 256

_repr = reprlib.Repr()
_repr.maxstring = _repr.maxother = 80
_repr.maxlevel = 3


def show(value):
    """A value in a message: its repr, shortened (long texts, deep or long lists)."""
    return _repr.repr(value)


def clipped(path):
    """A path in a message, shortened when long."""
    return path if len(path) <= 200 else path[:120] + "..." + path[-60:]


class StudyError(ValueError):
    """A study file that cannot be run: the message names the key and the value (one line, at most 2000
    characters: a long path or key is cut in the middle)."""

    def __init__(self, message):
        message = " ".join(str(message).split())
        super().__init__(message if len(message) <= 2000 else message[:1400] + " ... " + message[-500:])


def _mapping(study, key, default, path):
    value = study.get(key)
    value = default if value is None else value
    if not isinstance(value, dict):
        raise StudyError("%s: %s: expected a mapping of override keys to values, got %s" % (path, key, show(value)))
    for k, v in value.items():
        _check_override(k, v, "%s: %s" % (path, key))
    return value


def _check_override(key, value, where):
    """An override's key (a non-empty text) and value (a number, text, boolean, null, or a list or mapping of
    them), or StudyError naming them."""
    if not isinstance(key, str) or not key:
        raise StudyError("%s: the key %s is not an override key (a text, as analysis.steps)" % (where, show(key)))
    stack = [(value, key)]
    while stack:
        item, name = stack.pop()
        if isinstance(item, dict):
            for k, v in item.items():
                if not isinstance(k, str):
                    raise StudyError("%s.%s: the key %s is not a text" % (where, name, show(k)))
                stack.append((v, "%s.%s" % (name, k)))
        elif isinstance(item, list):
            stack += [(v, "%s[%d]" % (name, i)) for i, v in enumerate(item)]
        elif isinstance(item, (datetime.date, datetime.datetime)):
            raise StudyError("%s.%s: %s is read as a date: quote it to pass it as text" % (where, name, item))
        elif not (item is None or isinstance(item, (bool, int, float, str))):
            raise StudyError("%s.%s: expected a number, text, boolean, list or mapping, got %s (%s)"
                             % (where, name, show(item), type(item).__name__))


def _check_tree(document, where):
    """StudyError when the YAML read nests deeper than MAX_DEPTH or holds more than MAX_VALUES values."""
    stack, count = [(document, 0)], 0
    while stack:
        item, depth = stack.pop()
        count += 1
        if count > MAX_VALUES:
            raise StudyError("%s: more than %d values (an alias counts at each use)" % (where, MAX_VALUES))
        if depth > MAX_DEPTH:
            raise StudyError("%s: nested deeper than %d levels" % (where, MAX_DEPTH))
        if isinstance(item, dict):
            stack += [(v, depth + 1) for v in item.values()] + [(k, depth + 1) for k in item]
        elif isinstance(item, (list, tuple)):
            stack += [(v, depth + 1) for v in item]
        elif isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError:
                raise StudyError("%s: the text %s holds a lone surrogate (not a character)" % (where, show(item))) \
                    from None


def _load_yaml(text, where):
    """YAML text as Python values, or StudyError naming where (a syntax error, or nesting deeper than the
    parser's recursion)."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise StudyError("%s: YAML: %s" % (where, " ".join(str(e).split()))) from None
    except RecursionError:
        raise StudyError("%s: nested deeper than %d levels" % (where, MAX_DEPTH)) from None
    _check_tree(value, where)
    return value


def _read_text(path, where):
    """A file's text (UTF-8), or StudyError saying where and why it cannot be read."""
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_BYTES + 1)
    except OSError as e:
        raise StudyError("%s: cannot read it (%s)" % (where, e.strerror or e)) from None
    if len(data) > MAX_BYTES:
        raise StudyError("%s: larger than %d bytes" % (where, MAX_BYTES))
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise StudyError("%s: not UTF-8 text (byte 0x%02x at offset %d)" % (where, data[e.start], e.start)) \
            from None


def value_text(value):
    """A value as an override and a file name show it (booleans as YAML writes them, floats in their shortest
    exact form): the API's own override text."""
    from active_tensegrity import _value_text
    return _value_text(value)


def file_stem(template, overrides, where):
    """The template with each {key} replaced by the point's value of that override."""
    def value(match):
        key = match.group(1)
        if key not in overrides:
            raise StudyError("%s: save.name: the point %s has no value for {%s}" % (where, show(overrides), key))
        return value_text(overrides[key])
    stem = re.sub(r"\{([^{}]+)\}", value, template)
    if not stem or "/" in stem or "\0" in stem or stem in (".", "..") or len(stem.encode()) > 200:
        raise StudyError("%s: save.name: %s gives the file name %s for the point %s"
                         % (where, show(template), show(stem), show(overrides)))
    return stem


def _read_save(study, path, points):
    save = study.get("save")
    if save is None:
        return None
    if not isinstance(save, dict) or set(save) - {"name", "files"} or not isinstance(save.get("name"), str):
        raise StudyError("%s: save: expected {name: a file stem template, files: [%s]}, got %s"
                         % (path, ", ".join(SAVED_FILES), show(save)))
    files = save.get("files", ["table", "summary"])
    if isinstance(files, str):
        files = [files]
    if not isinstance(files, list) or not files or \
            any(not isinstance(f, str) or f not in SAVED_FILES for f in files):
        raise StudyError("%s: save.files: expected a list of %s, got %s"
                         % (path, ", ".join(SAVED_FILES), show(files)))
    stems = [file_stem(save["name"], p, path) for p in points]
    seen = {}
    for stem, p in zip(stems, points):
        if stem in seen and seen[stem] != p:
            raise StudyError("%s: save.name: the points %s and %s both give the name %r"
                             % (path, show(seen[stem]), show(p), stem))
        seen[stem] = p
    return {"stems": stems, "files": list(dict.fromkeys(files))}


def _read_plots(study, path):
    plots = study.get("plots", []) or []
    if not isinstance(plots, list):
        raise StudyError("%s: plots: expected a list of {x, y, by, file}, got %s" % (path, show(plots)))
    out = []
    for i, p in enumerate(plots):
        where = "%s: plots[%d]" % (path, i)
        if not isinstance(p, dict) or set(p) - {"x", "y", "by", "file", "title", "logx", "logy"}:
            raise StudyError("%s: expected a mapping with x, y, by, file, title, logx, logy, got %s"
                             % (where, show(p)))
        y = p.get("y")
        y = [y] if isinstance(y, str) else y
        if not isinstance(p.get("x"), str) or not isinstance(y, list) or not y or \
                not all(isinstance(c, str) for c in y):
            raise StudyError("%s: x: a column of results.csv, y: one or a list of them, got x=%s, y=%s"
                             % (where, show(p.get("x")), show(p.get("y"))))
        f = p.get("file")
        if not isinstance(f, str) or not f.endswith((".png", ".pdf", ".svg")) or "/" in f or "\0" in f:
            raise StudyError("%s: file: a file name ending .png, .pdf or .svg, got %s" % (where, show(f)))
        if "by" in p and not isinstance(p["by"], str):
            raise StudyError("%s: by: a column of results.csv, got %s" % (where, show(p["by"])))
        if "title" in p and not isinstance(p["title"], str):
            raise StudyError("%s: title: a text, got %s" % (where, show(p["title"])))
        for flag in ("logx", "logy"):
            if flag in p and not isinstance(p[flag], bool):
                raise StudyError("%s: %s: true or false, got %s" % (where, flag, show(p[flag])))
        out.append(dict(p, y=y))
    return out


def _names(value, where, what):
    """collect.summary or collect.final: a list of names (one name: a list of it), or StudyError."""
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise StudyError("%s: expected %s (a name or a list of names), got %s" % (where, what, show(value)))
    return list(dict.fromkeys(value))


def _check_summary_field(field, where):
    """A collect.summary entry: a field of the run's summary that is a number or a text (warnings: the list
    joined), or an entry of one of its mappings by a dotted name (peaks.max_normal_force.value)."""
    parts = field.split(".")
    if parts[0] in SUMMARY_FIELDS and len(parts) == 1:
        return
    if parts[0] in SUMMARY_MAPPINGS:
        entries, fields = SUMMARY_MAPPINGS[parts[0]]
        example = ".".join([parts[0], entries[0]] + (fields.get(entries[0], []) if isinstance(fields, dict)
                                                     else fields)[:1])
        if len(parts) == 1:
            raise StudyError("%s: %r is a mapping, not one figure: name an entry of it (as %s)%s"
                             % (where, field, example,
                                "; collect.peaks collects a column's max or min" if field == "peaks" else ""))
        if parts[1] not in entries:
            raise StudyError("%s: %r: %s has no entry %r (its entries: %s)"
                             % (where, field, parts[0], parts[1], ", ".join(entries)))
        if isinstance(fields, dict):
            fields = fields.get(parts[1], [])
            if fields:
                example = ".".join(parts[:2] + fields[:1])
        if (len(parts) == 2 and fields) or (len(parts) > 2 and (len(parts) > 3 or parts[2] not in fields)):
            raise StudyError("%s: %r: name one figure, as %s" % (where, field, example))
        return
    if parts[0] == "final":
        raise StudyError("%s: %r: collect.final collects a column's last value" % (where, field))
    raise StudyError("%s: unknown summary field %r (fields: %s; entries of %s by a dotted name, as "
                     "peaks.max_normal_force.value)" % (where, field, ", ".join(SUMMARY_FIELDS),
                                                        ", ".join(SUMMARY_MAPPINGS)))


def _read_collect(study, path):
    collect = study.get("collect")
    collect = {} if collect is None else collect
    if not isinstance(collect, dict) or set(collect) - {"summary", "peaks", "final"}:
        raise StudyError("%s: collect: expected a mapping with summary, peaks and final, got %s"
                         % (path, show(collect)))
    summary = collect.get("summary")
    summary = _names(DEFAULT_SUMMARY if summary is None else summary, path + ": collect.summary",
                     "summary fields")
    for field in summary:
        _check_summary_field(field, path + ": collect.summary")
    peaks = collect.get("peaks")
    peaks = {} if peaks is None else peaks
    if not isinstance(peaks, dict) or any(not isinstance(k, str) or not k or v not in ("max", "min")
                                          for k, v in peaks.items()):
        raise StudyError("%s: collect.peaks: expected {column: max or min}, got %s" % (path, show(peaks)))
    final = collect.get("final")
    final = _names([] if final is None else final, path + ": collect.final", "columns")
    return {"summary": summary, "peaks": dict(peaks), "final": final}


def read_study(path, sets=None):
    """The study file at path, checked: a dict with scene (its path made absolute), the scene's text, the points'
    overrides (in order; sets, {key: value}, over every point), what to collect, what to save and plot. A file
    that cannot be run raises StudyError naming the key and the value."""
    if not isinstance(path, (str, os.PathLike)) or "\0" in os.fsdecode(path):
        raise StudyError("the study file: expected a path, got %s" % show(path))
    where = clipped(os.fsdecode(path))
    study = _load_yaml(_read_text(path, where), where)
    if not isinstance(study, dict):
        raise StudyError("%s: expected a mapping (%s), got %s" % (where, ", ".join(STUDY_KEYS), show(study)))
    unknown = [k for k in study if k not in STUDY_KEYS]
    if unknown:
        raise StudyError("%s: unknown keys %s (known: %s)" % (where, show(unknown), ", ".join(STUDY_KEYS)))
    if not isinstance(study.get("scene"), str) or not study["scene"] or "\0" in study["scene"]:
        raise StudyError("%s: scene: expected the path of a scene file, got %s" % (where, show(study.get("scene"))))
    scene = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(path)), study["scene"]))
    if not os.path.isfile(scene):
        raise StudyError("%s: scene: no file at %s" % (where, clipped(scene)))
    text = _read_text(scene, "%s: scene: %s" % (where, clipped(scene)))
    common = _mapping(study, "set", {}, where)
    grid = _mapping(study, "grid", {}, where)
    count = 1
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise StudyError("%s: grid.%s: expected a non-empty list of values, got %s" % (where, key, show(values)))
        count *= len(values)
    listed = study.get("points")
    listed = [] if listed is None else listed
    if not isinstance(listed, list) or not all(isinstance(p, dict) for p in listed):
        raise StudyError("%s: points: expected a list of mappings of override keys to values, got %s"
                         % (where, show(listed)))
    for i, p in enumerate(listed):
        for k, v in p.items():
            _check_override(k, v, "%s: points[%d]" % (where, i))
    for k, v in (sets or {}).items():
        _check_override(k, v, "--set")
    keys = list(grid)
    count = (count if keys else 0) + len(listed)
    if count > MAX_POINTS:
        raise StudyError("%s: %d points (grid and points): more than %d" % (where, count, MAX_POINTS))
    points = []
    for combination in itertools.product(*(grid[k] for k in keys)) if keys else []:
        points.append(dict(common, **dict(zip(keys, combination))))
    points += [dict(common, **p) for p in listed]
    if not points:
        raise StudyError("%s: no points: give a grid or points" % where)
    points = [dict(p, **(sets or {})) for p in points]
    collect = _read_collect(study, where)
    return {
        "scene": scene,
        "text": text,
        "points": points,
        "parameters": list(dict.fromkeys(keys + [k for p in listed for k in p])),  # what varies, in order
        "summary": collect["summary"],
        "peaks": collect["peaks"],
        "final": collect["final"],
        "save": _read_save(study, where, points),
        "plots": _read_plots(study, where),
    }


def peak_column(column, kind):
    """The results column of a peak: max_<column> or min_<column> (the column itself when its name already
    starts so, as max_normal_force)."""
    return column if column.startswith(kind + "_") else "%s_%s" % (kind, column)


def point_id(overrides):
    """A name for a point that depends only on its overrides (the key of its kept result)."""
    text = json.dumps(overrides, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def tensegrity_run():
    """The path of the tensegrity_run program beside this package's compiled module (<prefix>/lib/active_tensegrity/
    in a devel or install space), or $ACTIVE_TENSEGRITY_RUN."""
    if os.environ.get("ACTIVE_TENSEGRITY_RUN"):
        return os.environ["ACTIVE_TENSEGRITY_RUN"]
    from active_tensegrity import _core
    folder = os.path.dirname(os.path.abspath(_core.__file__))
    while folder != os.path.dirname(folder):
        if os.path.basename(folder) == "lib":
            program = os.path.join(folder, "active_tensegrity", "tensegrity_run")
            if os.access(program, os.X_OK):
                return program
            break
        folder = os.path.dirname(folder)
    found = shutil.which("tensegrity_run")
    if found:
        return found
    raise FileNotFoundError("tensegrity_run: not found beside %s (set ACTIVE_TENSEGRITY_RUN to its path)"
                            % _core.__file__)


def _summary_value(values, field):
    """A collect.summary field of a run's summary (a dict): its value (warnings: joined by "; "), or None when
    the run has no such figure (duration of a static run, adaptive_steps of fixed steps)."""
    value = values
    for part in field.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    if isinstance(value, list):
        return "; ".join(str(v) for v in value)
    if isinstance(value, dict):  # read_study admits no such field
        raise TypeError("summary field %r is a mapping" % field)
    return value


def _extreme(values, times, kind):
    """The largest (kind max) or smallest value of a column over rows, and the time of the first row with it;
    NaN at the first NaN; NaN, NaN without rows."""
    import numpy as np
    if not len(values):
        return float("nan"), float("nan")
    nan = np.flatnonzero(np.isnan(values))
    i = int(nan[0]) if len(nan) else int(np.argmax(values) if kind == "max" else np.argmin(values))
    return float(values[i]), float(times[i])


def _collect(values, final_rows, summary, final):
    """What is collected from a run's summary (a dict) and its rows ({column: numpy array}) but the peaks."""
    out = {field: _summary_value(values, field) for field in summary}
    out["status"], out["message"] = values["status"], values.get("message") or ""
    for column in final:
        rows = final_rows[column]
        out["final_" + column] = float(rows[-1]) if len(rows) else float("nan")
    return out


def _check_columns(model, peaks, final):
    """StudyError naming a collected column that the point's run does not write."""
    columns = model.columns + model.member_columns
    for what, names in (("collect.peaks", list(peaks)), ("collect.final", final)):
        for name in names:
            if name not in columns:
                raise StudyError("%s: no column %r in this point's run (its columns: %s; members: %s)"
                                 % (what, name, ", ".join(model.columns), ", ".join(model.member_columns[1:])))


def _peak_from_files(column, kind, rows, values):
    """A peak over every step of a run tensegrity_run wrote, from its files, or None where they do not give it:
    its rows are every step in a static run (a row per load step) or a dynamic one with a row per step; otherwise
    the summary's peaks (the largest magnitude over every step but the start, with its sign) give a max that is
    >= 0 and a min that is <= 0, the start being the first row."""
    value, t = _extreme(rows[column], rows["t"], kind)
    if values.get("analysis") == "static" or values.get("output_steps") == (values.get("solver_steps") or 0) + 1:
        return value, t
    peak = (values.get("peaks") or {}).get(column)
    if not isinstance(peak, dict) or not isinstance(peak.get("value"), (int, float)) or math.isnan(value):
        return None
    v, at_t = float(peak["value"]), float(peak["t"])
    if not (v >= 0.0 if kind == "max" else v <= 0.0):
        return None
    # 0 at t = 0 is the summary's figure when no step passed 0, or when no step was taken: then only a start on
    # the side of 0 that a step would have left out tells them apart
    start = float(rows[column][0])
    if v == 0.0 and at_t == 0.0 and (start < 0.0 if kind == "max" else start > 0.0):
        return None
    beyond = value > v if kind == "max" else value < v  # only the start can be: every other row is a step
    return (value, t) if beyond or (value == v and t < at_t) else (v, at_t)


def _run_saving(model, text, name, overrides, collect, stem, files):
    """A point run by tensegrity_run, which writes its files; they come back as texts in out["files"] (a worker on
    another machine shares no folder with the study). Its peaks come from the files where they give them
    (_peak_from_files), else from the point run again in-process with the columns tracked."""
    import numpy as np
    import active_tensegrity as at
    with tempfile.TemporaryDirectory(prefix="active_tensegrity_study_") as tmp:
        scene = os.path.join(tmp, "scene.yaml")
        with open(scene, "w") as f:
            f.write(text)
        # the table and summary always (what is collected comes from them), the members' table for its columns
        paths = {kind: os.path.join(tmp, stem + SAVED_FILES[kind][1])
                 for kind in set(files) | {"table", "summary", "members"}}
        command = [tensegrity_run(), scene]
        for o in at._overrides(overrides):
            command += ["--set", o]
        for kind, path in paths.items():
            command += [SAVED_FILES[kind][0], path]
        done = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode not in (0, 3) or not os.path.exists(paths["summary"]):
            raise RuntimeError("tensegrity_run exited with %d: %s" % (done.returncode, done.stderr.strip()[-2000:]))
        texts = {}
        for kind in paths:
            with open(paths[kind]) as f:
                texts[kind] = f.read()
    # the summary names the scene file it ran: the study's scene, not the worker's copy
    texts["summary"] = re.sub(r"\Ascene: [^\n]*", lambda m: "scene: " + name, texts["summary"], count=1)
    values = yaml.safe_load(texts["summary"])
    values["scene"] = name
    rows = {}
    for kind in ("members", "table"):  # the table's columns over the members' (both have t)
        lines = texts[kind].splitlines()
        names = lines[0].split(",")
        # an empty field is +inf (tensegrity_run's "no value": min_gap where no strut pair is checked)
        table = np.array([[float(x) if x else np.inf for x in line.split(",")] for line in lines[1:]])
        table = table.reshape(-1, len(names))
        rows.update({c: table[:, i] for i, c in enumerate(names)})
    out = _collect(values, rows, collect["summary"], collect["final"])
    peaks, again = {}, []
    for column, kind in collect["peaks"].items():
        peaks[column] = _peak_from_files(column, kind, rows, values)
        if peaks[column] is None:
            again.append(column)
    if again:
        tracked = at.run(model, extremes=again).extremes
        for column in again:
            e = tracked[column][collect["peaks"][column]]
            peaks[column] = e["value"], e["t"]
    for column, kind in collect["peaks"].items():
        out[peak_column(column, kind)], out[peak_column(column, kind) + "_t"] = peaks[column]
    out["files"] = {stem + SAVED_FILES[kind][1]: texts[kind] for kind in files}
    return out


def run_point(text, name, overrides, collect, save=None):
    """Runs one point (in a worker): a dict of what is collected (collect: summary fields, {column: max or min}
    peaks over every step with their times, final columns), with status and message always. save: (stem, files)
    to run it with tensegrity_run and return those files' texts under "files"."""
    import active_tensegrity as at  # imported in the worker's process
    out = {"status": "", "message": ""}
    try:
        model = at.load(text, overrides, name=name)
        _check_columns(model, collect["peaks"], collect["final"])
        if save:
            return _run_saving(model, text, name, overrides, collect, *save)
        result = at.run(model, extremes=list(collect["peaks"]))
        out = _collect(dict(result.summary, scene=name), result, collect["summary"], collect["final"])
        for column, kind in collect["peaks"].items():
            e = result.extremes[column][kind]
            out[peak_column(column, kind)], out[peak_column(column, kind) + "_t"] = e["value"], e["t"]
        return out
    except at.SceneError as e:
        out.update(status="refused", message=str(e))
    except Exception as e:  # a failed point is recorded, never fatal to the study
        out.update(status="error", message="%s: %s" % (type(e).__name__, e))
    return out


def _columns(study):
    cols = ["point"] + study["parameters"]
    cols += [f for f in study["summary"] if f not in ("status", "message")] + ["status", "message"]
    for c, k in study["peaks"].items():
        cols += [peak_column(c, k), peak_column(c, k) + "_t"]
    cols += ["final_" + c for c in study["final"]]
    return cols


def _collect_spec(study):
    """What a point's record was collected for: its kept result is reused for the same."""
    return {"format": RECORD_FORMAT, "summary": study["summary"], "peaks": study["peaks"], "final": study["final"]}


def _digest(text):
    return hashlib.sha1(text.encode()).hexdigest()


def _done(kept, out, i, spec):
    """Whether point i is kept, collected for spec (_collect_spec), with every file it saved as it saved it
    (another run may have written over a file of the same name)."""
    try:
        with open(os.path.join(kept, i + ".json")) as f:
            record = json.load(f)
        if record.get("collect") != spec:
            return False
        for name, digest in record.get("files", {}).items():
            with open(os.path.join(out, name)) as f:
                if _digest(f.read()) != digest:
                    return False
    except (OSError, ValueError, AttributeError):
        return False
    return True


def _write(path, text):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def make_plots(study, table, out):
    """The study's plots of results.csv into out; returns their paths."""
    if not study["plots"]:
        return []
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    with open(table, newline="") as f:
        rows = list(csv.DictReader(f))

    def number(text):
        try:
            return float(text)
        except ValueError:
            return None

    made = []
    for p in study["plots"]:
        for column in [p["x"]] + p["y"] + ([p["by"]] if "by" in p else []):
            if rows and column not in rows[0]:
                raise StudyError("plots: %r is not a column of %s (its columns: %s)"
                                 % (column, table, ", ".join(rows[0])))
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        groups = {}
        for r in rows:
            groups.setdefault(r[p["by"]] if "by" in p else None, []).append(r)
        for group, members in groups.items():
            for y in p["y"]:
                points = sorted((number(r[p["x"]]), number(r[y])) for r in members
                                if number(r[p["x"]]) is not None and number(r[y]) is not None)
                if not points:
                    continue
                label = ", ".join(x for x in ((y if len(p["y"]) > 1 else None),
                                              ("%s = %s" % (p["by"], group) if group is not None else None)) if x)
                ax.plot([a for a, _ in points], [b for _, b in points], "o-", label=label or None)
        ax.set_xlabel(p["x"])
        ax.set_ylabel(", ".join(p["y"]))
        if p.get("logx"):
            ax.set_xscale("log")
        if p.get("logy"):
            ax.set_yscale("log")
        ax.set_title(p.get("title", os.path.basename(out)), fontsize=10)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        target = os.path.join(out, p["file"])
        fig.savefig(target, dpi=120)
        plt.close(fig)
        made.append(target)
    return made


def _client(scheduler, workers):
    """A dask client of the scheduler at that address, or of a new local cluster; StudyError when the scheduler
    cannot be reached."""
    from dask.distributed import Client, LocalCluster
    if scheduler:
        try:
            return Client(scheduler), None
        except Exception as e:  # refused, timed out, not a scheduler: dask's errors vary
            raise StudyError("--scheduler %s: cannot connect (%s: %s)"
                             % (scheduler, type(e).__name__, " ".join(str(e).split())[:300])) from None
    cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    return Client(cluster), cluster


def run_study(path, out=None, scheduler=None, workers=None, progress=True, sets=None):
    """Runs the study file at path (sets: {key: value} over every point); returns the path of results.csv.
    Points already in out/points (collected alike, with their saved files) are not run again."""
    study = read_study(path, sets)
    out = out or os.path.splitext(os.path.abspath(path))[0]
    kept = os.path.join(out, "points")
    try:
        os.makedirs(kept, exist_ok=True)
    except OSError as e:
        raise StudyError("--out %s: cannot make the folder %s (%s)" % (out, kept, e.strerror or e)) from None
    ids = [point_id(p) for p in study["points"]]
    save = study["save"]
    stems = dict(zip(ids, save["stems"])) if save else {}
    spec = _collect_spec(study)
    collect = {k: study[k] for k in ("summary", "peaks", "final")}
    todo = [(i, p) for i, p in zip(ids, study["points"]) if not _done(kept, out, i, spec)]
    todo = list({i: (i, p) for i, p in todo}.values())  # a point listed twice runs once
    if todo:
        from dask.distributed import as_completed
        client, cluster = _client(scheduler, workers)
        try:
            futures = {}
            for i, p in todo:
                f = client.submit(run_point, study["text"], study["scene"], p, collect,
                                  (stems[i], save["files"]) if save else None, key="point-" + i, pure=False)
                futures[f] = (i, p)
            bar = None
            if progress:
                from tqdm import tqdm
                bar = tqdm(total=len(futures), desc=os.path.basename(path), unit="point", file=sys.stderr)
            for f in as_completed(futures):
                i, p = futures[f]
                try:
                    collected = f.result()
                except Exception as e:  # the worker died or could not import the package
                    collected = {"status": "error", "message": "%s: %s" % (type(e).__name__, e)}
                files = collected.pop("files", {})
                for name, text in files.items():
                    _write(os.path.join(out, name), text)
                record = {"overrides": p, "collect": spec, "collected": collected,
                          "files": {name: _digest(text) for name, text in sorted(files.items())}}
                _write(os.path.join(kept, i + ".json"), json.dumps(record, default=str))
                if bar:
                    bar.update(1)
            if bar:
                bar.close()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    columns = _columns(study)
    table = os.path.join(out, "results.csv")
    with open(table, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(columns)
        for i, p in zip(ids, study["points"]):
            with open(os.path.join(kept, i + ".json")) as pf:
                collected = json.load(pf)["collected"]
            row = dict({k: value_text(v) for k, v in p.items()}, point=i, **collected)
            writer.writerow(["" if row.get(c) is None else row.get(c, "") for c in columns])
    make_plots(study, table, out)
    return table


def parse_set(text):
    """--set KEY=VALUE: the value read as YAML (as in a study file)."""
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise StudyError("--set: expected KEY=VALUE, got %s" % show(text))
    value = _load_yaml(value, "--set %s" % key) if value else ""
    _check_override(key, value, "--set")
    return key, value


# a dask scheduler's address: [PROTOCOL://]HOST[:PORT]
SCHEDULER = re.compile(r"\A(?:(?:tcp|tls|ws|wss|ucx)://)?(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9][A-Za-z0-9._-]*)"
                       r"(?::(\d{1,5}))?\Z")


def main(argv=None):
    """The study command: 0 when the study ran (or, with --check, reads), 1 when it cannot be run (the study file,
    a --set value, the results folder, an unreachable scheduler; a line on stderr names the key and value), 2 for
    arguments it does not take (argparse's status), 130 when interrupted."""
    parser = argparse.ArgumentParser(prog="python3 -m active_tensegrity.study",
                                     description="Runs a parameter study (a scene, many overrides) on dask")
    parser.add_argument("study", help="the study file (YAML)")
    parser.add_argument("--scheduler", help="a dask scheduler's address (tcp://HOST:8786); default: a local cluster")
    parser.add_argument("--workers", type=int, help="local cluster: worker processes (default: the cores)")
    parser.add_argument("--out", help="the results folder (default: the study file's name, beside it)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override KEY in every point (over the study file's values); repeatable")
    parser.add_argument("--check", action="store_true",
                        help="read and check the study file, print its points and results columns; run nothing")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.workers is not None and not 1 <= args.workers <= MAX_WORKERS:
        parser.error("--workers: 1 to %d, got %d" % (MAX_WORKERS, args.workers))
    if args.scheduler is not None:
        port = SCHEDULER.match(args.scheduler)
        if not port or (port.group(1) is not None and not 1 <= int(port.group(1)) <= 65535):
            parser.error("--scheduler: expected a scheduler's address, as tcp://HOST:8786, got %s"
                         % show(args.scheduler))
        if args.workers is not None:
            parser.error("--workers: for a local cluster; --scheduler's workers are its own")
    for option, value in (("study", args.study), ("--out", args.out)):
        if value is not None and (not value or "\0" in value):
            parser.error("%s: expected a path, got %s" % (option, show(value)))
    try:
        sets = dict(parse_set(t) for t in args.set)
        if args.check:
            study = read_study(args.study, sets)
            print("%s: %d points; results.csv columns: %s" % (args.study, len(study["points"]),
                                                                 ", ".join(_columns(study))))
            return 0
        table = run_study(args.study, args.out, args.scheduler, args.workers, not args.no_progress, sets)
    except StudyError as e:
        print("study: %s" % " ".join(str(e).split()), file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("study: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # OSError (a full disk), a missing module (dask, tqdm, matplotlib): one line, no traceback
        print("study: %s: %s" % (type(e).__name__, " ".join(str(e).split())[:2000]), file=sys.stderr)
        return 1
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
