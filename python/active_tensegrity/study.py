"""Parameter studies on dask.distributed: one scene, many overrides, one table of results.

    python3 -m active_tensegrity.study STUDY.yaml [--scheduler tcp://HOST:8786] [--workers N] [--out DIR]

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
      peaks: {max_normal_force: max, height: min}                # a column's largest or smallest value
      final: [height, actuation]                                 # a column's last value
    save:                                       # optional: each point's files, as tensegrity_run writes them
      name: "r{struts.radius}_h{analysis.max_actuation}"   # their stem; {key}: the point's value of key
      files: [table, summary, contacts]         # <name>.csv, <name>.yaml, <name>_contacts.csv (also: nodes, members)
    plots:                                      # optional: figures of results.csv (matplotlib)
      - {x: analysis.max_actuation, y: [min_height], by: struts.radius, file: height.png}

Without --scheduler the points run on a LocalCluster of --workers processes (default: the machine's cores);
with it, on the cluster of that scheduler (dask-scheduler, and dask-worker on each machine, every worker with
this package installed and its environment sourced). The scene travels as text: workers need no copy of it.

Results go to --out (default: the study file's name without .yaml, beside it): points/<id>.json per point
(its overrides and what was collected), kept across runs, so a re-run computes only the points not yet done;
results.csv, one row per point in the study's order; the saved files and the plots. A point that fails (a
refused scene, a run that stops) is recorded with its status and message; the study goes on. --set KEY=VALUE
(repeatable) overrides KEY in every point, over the study file's values. docs/python.md describes it.
"""

import argparse
import csv
import hashlib
import itertools
import json
import os
import re
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


class StudyError(ValueError):
    """A study file that cannot be run: the message names the key and the value."""


def _mapping(study, key, default):
    value = study.get(key, default)
    if not isinstance(value, dict):
        raise StudyError("%s: expected a mapping of override keys to values, got %r" % (key, value))
    return value


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
            raise StudyError("%s: save.name: the point %s has no value for {%s}" % (where, overrides, key))
        return value_text(overrides[key])
    stem = re.sub(r"\{([^{}]+)\}", value, template)
    if not stem or "/" in stem or stem in (".", ".."):
        raise StudyError("%s: save.name: %r gives the file name %r for the point %s"
                         % (where, template, stem, overrides))
    return stem


def _read_save(study, path, points):
    save = study.get("save")
    if save is None:
        return None
    if not isinstance(save, dict) or set(save) - {"name", "files"} or not isinstance(save.get("name"), str):
        raise StudyError("%s: save: expected {name: a file stem template, files: [%s]}, got %r"
                         % (path, ", ".join(SAVED_FILES), save))
    files = save.get("files", ["table", "summary"])
    if not isinstance(files, list) or not files or any(f not in SAVED_FILES for f in files):
        raise StudyError("%s: save.files: expected a list of %s, got %r" % (path, ", ".join(SAVED_FILES), files))
    stems = [file_stem(save["name"], p, path) for p in points]
    seen = {}
    for stem, p in zip(stems, points):
        if stem in seen and seen[stem] != p:
            raise StudyError("%s: save.name: the points %s and %s both give the name %r"
                             % (path, seen[stem], p, stem))
        seen[stem] = p
    return {"stems": stems, "files": list(dict.fromkeys(files))}


def _read_plots(study, path):
    plots = study.get("plots", []) or []
    if not isinstance(plots, list):
        raise StudyError("%s: plots: expected a list of {x, y, by, file}, got %r" % (path, plots))
    out = []
    for i, p in enumerate(plots):
        where = "%s: plots[%d]" % (path, i)
        if not isinstance(p, dict) or set(p) - {"x", "y", "by", "file", "title", "logx", "logy"}:
            raise StudyError("%s: expected a mapping with x, y, by, file, title, logx, logy, got %r" % (where, p))
        y = p.get("y")
        y = [y] if isinstance(y, str) else y
        if not isinstance(p.get("x"), str) or not isinstance(y, list) or not y or \
                not all(isinstance(c, str) for c in y):
            raise StudyError("%s: x: a column of results.csv, y: one or a list of them, got x=%r, y=%r"
                             % (where, p.get("x"), p.get("y")))
        f = p.get("file")
        if not isinstance(f, str) or not f.endswith((".png", ".pdf", ".svg")) or "/" in f:
            raise StudyError("%s: file: a file name ending .png, .pdf or .svg, got %r" % (where, f))
        if "by" in p and not isinstance(p["by"], str):
            raise StudyError("%s: by: a column of results.csv, got %r" % (where, p["by"]))
        out.append(dict(p, y=y))
    return out


def read_study(path, sets=None):
    """The study file at path, checked: a dict with scene (its path made absolute), the scene's text, the points'
    overrides (in order; sets, {key: value}, over every point), what to collect, what to save and plot."""
    with open(path) as f:
        study = yaml.safe_load(f)
    if not isinstance(study, dict):
        raise StudyError("%s: expected a mapping (%s)" % (path, ", ".join(STUDY_KEYS)))
    unknown = set(study) - set(STUDY_KEYS)
    if unknown:
        raise StudyError("%s: unknown keys %s (known: %s)" % (path, sorted(unknown), ", ".join(STUDY_KEYS)))
    if not isinstance(study.get("scene"), str):
        raise StudyError("%s: scene: expected the path of a scene file, got %r" % (path, study.get("scene")))
    scene = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(path)), study["scene"]))
    if not os.path.isfile(scene):
        raise StudyError("%s: scene: no file at %s" % (path, scene))
    with open(scene) as f:
        text = f.read()
    common = _mapping(study, "set", {})
    grid = _mapping(study, "grid", {})
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise StudyError("%s: grid.%s: expected a non-empty list of values, got %r" % (path, key, values))
    listed = study.get("points", [])
    if not isinstance(listed, list) or not all(isinstance(p, dict) for p in listed):
        raise StudyError("%s: points: expected a list of mappings of override keys to values" % path)
    points = []
    keys = list(grid)
    for combination in itertools.product(*(grid[k] for k in keys)) if keys else []:
        points.append(dict(common, **dict(zip(keys, combination))))
    points += [dict(common, **p) for p in listed]
    if not points:
        raise StudyError("%s: no points: give a grid or points" % path)
    points = [dict(p, **(sets or {})) for p in points]
    collect = study.get("collect", {}) or {}
    if not isinstance(collect, dict) or set(collect) - {"summary", "peaks", "final"}:
        raise StudyError("%s: collect: expected a mapping with summary, peaks and final, got %r" % (path, collect))
    peaks = collect.get("peaks", {}) or {}
    if not isinstance(peaks, dict) or any(v not in ("max", "min") for v in peaks.values()):
        raise StudyError("%s: collect.peaks: expected {column: max or min}, got %r" % (path, peaks))
    return {
        "scene": scene,
        "text": text,
        "points": points,
        "parameters": list(dict.fromkeys(keys + [k for p in listed for k in p])),  # what varies, in order
        "summary": list(collect.get("summary", DEFAULT_SUMMARY) or DEFAULT_SUMMARY),
        "peaks": dict(peaks),
        "final": list(collect.get("final", []) or []),
        "save": _read_save(study, path, points),
        "plots": _read_plots(study, path),
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


def _collect(out, summary_values, table, summary, peaks, final):
    """Fills out from a run's summary (a dict) and its table ({column: numpy array})."""
    for field in summary:
        value = summary_values.get(field)
        out[field] = "; ".join(value) if isinstance(value, list) else value
    out["status"], out["message"] = summary_values["status"], summary_values["message"]
    for column, kind in peaks.items():
        values = table[column]
        out[peak_column(column, kind)] = \
            float(values.max() if kind == "max" else values.min()) if len(values) else float("nan")
    for column in final:
        values = table[column]
        out["final_" + column] = float(values[-1]) if len(values) else float("nan")
    return out


def _run_saving(text, name, overrides, summary, peaks, final, stem, files):
    """A point run by tensegrity_run, which writes its files; they come back as texts in out["files"] (a worker on
    another machine shares no folder with the study)."""
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
    values["message"] = values.get("message") or ""
    table = {}
    for kind in ("members", "table"):  # the table's columns over the members' (both have t)
        lines = texts[kind].splitlines()
        names = lines[0].split(",")
        # an empty field is +inf (tensegrity_run's "no value": min_gap where no strut pair is checked)
        rows = np.array([[float(x) if x else np.inf for x in line.split(",")] for line in lines[1:]])
        rows = rows.reshape(-1, len(names))
        table.update({c: rows[:, i] for i, c in enumerate(names)})
    columns = list(table)
    for column in list(peaks) + list(final):
        if column not in table:
            raise KeyError("no column %r in the table (its columns: %s)" % (column, ", ".join(columns)))
    out = _collect({"status": "", "message": ""}, values, table, summary, peaks, final)
    out["files"] = {stem + SAVED_FILES[kind][1]: texts[kind] for kind in files}
    return out


def run_point(text, name, overrides, summary, peaks, final, save=None):
    """Runs one point (in a worker): a dict of what is collected, with status and message always. save: (stem,
    files) to run it with tensegrity_run and return those files' texts under "files"."""
    import active_tensegrity as at  # imported in the worker's process
    out = {"status": "", "message": ""}
    try:
        model = at.load(text, overrides, name=name)
        if save:
            return _run_saving(text, name, overrides, summary, peaks, final, *save)
        result = at.run(model)
        return _collect(out, result.summary, result, summary, peaks, final)
    except at.SceneError as e:
        out.update(status="refused", message=str(e))
    except Exception as e:  # a failed point is recorded, never fatal to the study
        out.update(status="error", message="%s: %s" % (type(e).__name__, e))
    return out


def _columns(study):
    cols = ["point"] + study["parameters"]
    cols += [f for f in study["summary"] if f not in ("status", "message")] + ["status", "message"]
    cols += [peak_column(c, k) for c, k in study["peaks"].items()]
    cols += ["final_" + c for c in study["final"]]
    return cols


def _digest(text):
    return hashlib.sha1(text.encode()).hexdigest()


def _done(kept, out, i):
    """Whether point i is kept, with every file it saved as it saved it (another run may have written over a
    file of the same name)."""
    try:
        with open(os.path.join(kept, i + ".json")) as f:
            record = json.load(f)
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


def run_study(path, out=None, scheduler=None, workers=None, progress=True, sets=None):
    """Runs the study file at path (sets: {key: value} over every point); returns the path of results.csv.
    Points already in out/points (with their saved files) are not run again."""
    study = read_study(path, sets)
    out = out or os.path.splitext(os.path.abspath(path))[0]
    kept = os.path.join(out, "points")
    os.makedirs(kept, exist_ok=True)
    ids = [point_id(p) for p in study["points"]]
    save = study["save"]
    stems = dict(zip(ids, save["stems"])) if save else {}
    todo = [(i, p) for i, p in zip(ids, study["points"]) if not _done(kept, out, i)]
    todo = list({i: (i, p) for i, p in todo}.values())  # a point listed twice runs once
    if todo:
        from dask.distributed import Client, LocalCluster, as_completed
        cluster = None
        if scheduler:
            client = Client(scheduler)
        else:
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                                   processes=True, dashboard_address=None)
            client = Client(cluster)
        try:
            futures = {}
            for i, p in todo:
                f = client.submit(run_point, study["text"], study["scene"], p, study["summary"], study["peaks"],
                                  study["final"], (stems[i], save["files"]) if save else None, key="point-" + i,
                                  pure=False)
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
                record = {"overrides": p, "collected": collected,
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
        raise StudyError("--set: expected KEY=VALUE, got %r" % text)
    return key, yaml.safe_load(value) if value else ""


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python3 -m active_tensegrity.study",
                                     description="Runs a parameter study (a scene, many overrides) on dask")
    parser.add_argument("study", help="the study file (YAML)")
    parser.add_argument("--scheduler", help="a dask scheduler's address (tcp://HOST:8786); default: a local cluster")
    parser.add_argument("--workers", type=int, help="local cluster: worker processes (default: the cores)")
    parser.add_argument("--out", help="the results folder (default: the study file's name, beside it)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override KEY in every point (over the study file's values); repeatable")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.workers is not None and args.workers < 1:
        parser.error("--workers: at least 1, got %d" % args.workers)
    try:
        sets = dict(parse_set(t) for t in args.set)
        table = run_study(args.study, args.out, args.scheduler, args.workers, not args.no_progress, sets)
    except (StudyError, OSError, yaml.YAMLError) as e:
        print("study: %s" % e, file=sys.stderr)
        return 1
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
