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

Without --scheduler the points run on a LocalCluster of --workers processes (default: the machine's cores);
with it, on the cluster of that scheduler (dask-scheduler, and dask-worker on each machine, every worker with
this package installed and its environment sourced). The scene travels as text: workers need no copy of it.

Results go to --out (default: the study file's name without .yaml, beside it): points/<id>.json per point
(its overrides and what was collected), kept across runs, so a re-run computes only the points not yet done;
results.csv, one row per point in the study's order. A point that fails (a refused scene, a run that stops)
is recorded with its status and message; the study goes on. docs/python.md describes it.
"""

import argparse
import csv
import hashlib
import itertools
import json
import os
import sys

import yaml

DEFAULT_SUMMARY = ["status", "message"]


class StudyError(ValueError):
    """A study file that cannot be run: the message names the key and the value."""


def _mapping(study, key, default):
    value = study.get(key, default)
    if not isinstance(value, dict):
        raise StudyError("%s: expected a mapping of override keys to values, got %r" % (key, value))
    return value


def read_study(path):
    """The study file at path, checked: a dict with scene (its path made absolute), the scene's text, the points'
    overrides (in order) and what to collect."""
    with open(path) as f:
        study = yaml.safe_load(f)
    if not isinstance(study, dict):
        raise StudyError("%s: expected a mapping (scene, set, grid, points, collect)" % path)
    unknown = set(study) - {"scene", "set", "grid", "points", "collect"}
    if unknown:
        raise StudyError("%s: unknown keys %s (known: scene, set, grid, points, collect)" % (path, sorted(unknown)))
    if not isinstance(study.get("scene"), str):
        raise StudyError("%s: scene: expected the path of a scene file, got %r" % (path, study.get("scene")))
    scene = os.path.join(os.path.dirname(os.path.abspath(path)), study["scene"])
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
    }


def peak_column(column, kind):
    """The results column of a peak: max_<column> or min_<column> (the column itself when its name already
    starts so, as max_normal_force)."""
    return column if column.startswith(kind + "_") else "%s_%s" % (kind, column)


def point_id(overrides):
    """A name for a point that depends only on its overrides (the key of its kept result)."""
    text = json.dumps(overrides, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def run_point(text, name, overrides, summary, peaks, final):
    """Runs one point (in a worker): a dict of what is collected, with status and message always."""
    import active_tensegrity as at  # imported in the worker's process
    out = {"status": "", "message": ""}
    try:
        result = at.run(at.load(text, overrides, name=name))
    except at.SceneError as e:
        out.update(status="refused", message=str(e))
        return out
    except Exception as e:  # a failed point is recorded, never fatal to the study
        out.update(status="error", message="%s: %s" % (type(e).__name__, e))
        return out
    for field in summary:
        value = result.summary.get(field)
        out[field] = "; ".join(value) if isinstance(value, list) else value
    out["status"], out["message"] = result.summary["status"], result.summary["message"]
    for column, kind in peaks.items():
        values = result[column]
        out[peak_column(column, kind)] = \
            float(values.max() if kind == "max" else values.min()) if len(values) else float("nan")
    for column in final:
        values = result[column]
        out["final_" + column] = float(values[-1]) if len(values) else float("nan")
    return out


def _columns(study):
    cols = ["point"] + study["parameters"]
    cols += [f for f in study["summary"] if f not in ("status", "message")] + ["status", "message"]
    cols += [peak_column(c, k) for c, k in study["peaks"].items()]
    cols += ["final_" + c for c in study["final"]]
    return cols


def run_study(path, out=None, scheduler=None, workers=None, progress=True):
    """Runs the study file at path; returns the path of results.csv. Points already in out/points are not
    run again."""
    study = read_study(path)
    out = out or os.path.splitext(os.path.abspath(path))[0]
    kept = os.path.join(out, "points")
    os.makedirs(kept, exist_ok=True)
    ids = [point_id(p) for p in study["points"]]
    todo = [(i, p) for i, p in zip(ids, study["points"]) if not os.path.exists(os.path.join(kept, i + ".json"))]
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
                                  study["final"], key="point-" + i, pure=False)
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
                record = {"overrides": p, "collected": collected}
                tmp = os.path.join(kept, i + ".json.tmp")
                with open(tmp, "w") as fh:
                    json.dump(record, fh, default=str)
                os.replace(tmp, os.path.join(kept, i + ".json"))
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
            row = dict(p, point=i, **collected)
            writer.writerow(["" if row.get(c) is None else row.get(c, "") for c in columns])
    return table


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python3 -m active_tensegrity.study",
                                     description="Runs a parameter study (a scene, many overrides) on dask")
    parser.add_argument("study", help="the study file (YAML)")
    parser.add_argument("--scheduler", help="a dask scheduler's address (tcp://HOST:8786); default: a local cluster")
    parser.add_argument("--workers", type=int, help="local cluster: worker processes (default: the cores)")
    parser.add_argument("--out", help="the results folder (default: the study file's name, beside it)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.workers is not None and args.workers < 1:
        parser.error("--workers: at least 1, got %d" % args.workers)
    try:
        table = run_study(args.study, args.out, args.scheduler, args.workers, not args.no_progress)
    except (StudyError, OSError, yaml.YAMLError) as e:
        print("study: %s" % e, file=sys.stderr)
        return 1
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
