#!/usr/bin/env python3
"""Mutation fuzzer of tensegrity_run: runs the command on mutated shipped scenes and odd --set values and
sorts every outcome into one class.

  fuzz_run.py --bin PATH/tensegrity_run [--scenes DIR] [--cases N] [--seed S] [--timeout SEC] [--out DIR]

Classes (the first four are fine, the rest are defects):
  refused      exit 1, "scene refused:" with the key or the YAML line named
  bad_args     exit 2, a refused command line (an unparsable --set) with its reason
  ran          exit 0, every CSV and summary number finite
  stopped      exit 3, the solver's status and message, every number written finite
  unnamed      exit 1 or 2 without a key, a line or a reason in the message
  non_finite   a nan or inf in the CSV or the summary
  long_message more than 4000 bytes on stderr (a value echoed whole)
  crash        killed by a signal, or an exit status other than 0-3
  hang         still running after --timeout seconds
Each defect is saved in --out with its scene, its arguments and its output, and a line to reproduce it.
Every run is short: the base arguments cap the analysis (analysis.steps=4, analysis.duration=0.02) unless
a mutation sets those keys. Exit status: 0 without defects, 1 with any.
"""
import argparse
import collections
import math
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile

import yaml

BASE = ["--set", "analysis.steps=4", "--set", "analysis.duration=0.02"]

# values a user (or a script) may give: extremes, wrong types, odd YAML
VALUES = [
    "0", "-0.0", "-1", "1e-300", "1e300", "-1e300", "1e-9", "0.5", "2", "7", "1e9", "2147483648", "1e18",
    ".nan", ".inf", "-.inf", "nan", "inf", "true", "false", "null", "~", "''", "abc", "[]", "{}", "[1, 2, 3]",
    "[0, 0, 0]", "[1e300, 1e300, 1e300]", "{a: 1}", "[[1, 2], [3]]", "'x' ", "\"\\u0000\"", "0x10", "1_000",
    "[.nan, 0, 0]", "*alias", "&a [1]", "!!binary aGVsbG8=", "? a", "- - 1", "x" * 5000,
    "{radius: 1, radius: 2}", "1\n---\n2", "--- 1", "1e-3", "1e-2", "1e14", "1e5", "10",
]
KEYS_EXTRA = [
    "solver.max_step_cuts", "solver.max_iterations", "solver.dt", "solver.dt_min", "solver.dt_max", "solver.adaptive",
    "solver.newton_tolerance", "solver.max_jacobian_age", "solver.error_tolerance", "solver.integrator",
    "solver.newmark.gamma", "solver.newmark.beta", "solver.rho_infinity", "analysis.output_interval",
    "analysis.type", "analysis.max_actuation", "contact.enabled", "contact.friction", "contact.restitution",
    "contact.law", "contact.stiffness", "contact.damping", "ground.law", "ground.stiffness", "ground.damping",
    "contact.pairs", "contact.min_crossing_angle", "gravity.enabled", "gravity.vector", "damping.enabled",
    "actuation.speed", "actuation.blend_time", "actuation.start_time", "outputs.height_nodes", "struts.radius",
    "struts.core.radius", "struts.material", "analysis.duration.", ".analysis", "a..b", "analysis", "nodes",
    "struts.members", "x" * 3000, "solver.onset_depth", "struts.radious", "solver.newton_tolerence",
    "materials", "struts",
]

NUMBER = re.compile(r"(?<![\w.])-?\d+(\.\d+)?([eE][-+]?\d+)?(?![\w.])")
KEY_NAMED = re.compile(r"scene refused: .+?: \S.*?: \S|YAML syntax error|must be a YAML map|line \d+|cannot open|"
                       r"cannot write '")
FINITE_BAD = re.compile(r"(?<![\w])(-?inf|nan)(?![\w])", re.I)


def leaves(node, prefix=""):
    """Dotted paths of every leaf and map of a parsed scene."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            path = "%s.%s" % (prefix, k) if prefix else str(k)
            out.append(path)
            out.extend(leaves(v, path))
    return out


def mutate_text(text, rng, names):
    lines = text.split("\n")
    kind = rng.choice(["delete_line", "duplicate_line", "number", "name", "truncate", "bytes", "indent", "swap"])
    i = rng.randrange(len(lines))
    if kind == "delete_line":
        del lines[i]
    elif kind == "duplicate_line":
        lines.insert(i, lines[i])
    elif kind == "number":
        spots = [(n, m) for n, l in enumerate(lines) for m in NUMBER.finditer(l)]
        if spots:
            n, m = rng.choice(spots)
            lines[n] = lines[n][: m.start()] + rng.choice(VALUES[:20]) + lines[n][m.end():]
    elif kind == "name" and names:
        old, new = rng.choice(names), rng.choice(names + ["X", "", "a b", "x" * 300])
        lines[i] = re.sub(r"\b%s\b" % re.escape(old), new, lines[i])
    elif kind == "truncate":
        return "\n".join(lines)[: rng.randrange(max(1, len(text)))], kind
    elif kind == "bytes":
        pos = rng.randrange(len(text) + 1)
        junk = "".join(rng.choice(":{}[],-?&*!|>'\"#%@`\t\x00\x01é 0123abc\n") for _ in range(rng.randint(1, 6)))
        return text[:pos] + junk + text[pos:], kind
    elif kind == "indent":
        lines[i] = (" " * rng.choice([1, 2, 4]) + lines[i]) if rng.random() < 0.5 else lines[i].lstrip()
    elif kind == "swap":
        j = rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    return "\n".join(lines), kind


def classify(rc, out, err, csv_text, summary_text):
    if rc is None:
        return "hang"
    if rc < 0 or rc not in (0, 1, 2, 3):
        return "crash"
    if len(err) > 4000:
        return "long_message"
    if rc in (0, 3):
        for t in (csv_text, summary_text):
            for line in t.splitlines():
                if line.startswith(("scene:", "name:", "message:")):
                    continue
                if FINITE_BAD.search(line):
                    return "non_finite"
        return "ran" if rc == 0 else "stopped"
    if rc == 1:
        return "refused" if KEY_NAMED.search(err) else "unnamed"
    return "bad_args" if "tensegrity_run:" in err and len(err.splitlines()[0]) > 20 else "unnamed"


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bin", required=True, help="the tensegrity_run executable")
    p.add_argument("--scenes", default=os.path.join(here, "..", "config", "scenes"))
    p.add_argument("--cases", type=int, default=200)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--timeout", type=float, default=60.0)
    p.add_argument("--out", default=None, help="where defects are saved (default: a temporary folder)")
    a = p.parse_args()
    rng = random.Random(a.seed)
    scenes = sorted(os.path.join(a.scenes, f) for f in os.listdir(a.scenes) if f.endswith(".yaml"))
    out_dir = a.out or tempfile.mkdtemp(prefix="fuzz_run_")
    os.makedirs(out_dir, exist_ok=True)
    work = tempfile.mkdtemp(prefix="fuzz_run_work_")
    counts = collections.Counter()
    by_kind = collections.defaultdict(collections.Counter)
    defects = 0
    try:
        for case in range(a.cases):
            path = rng.choice(scenes)
            text = open(path).read()
            parsed = yaml.safe_load(text)
            names = [str(k) for k in (parsed.get("nodes") or {})] + [
                str(k) for k in ((parsed.get("struts") or {}).get("members") or {})]
            args = list(BASE)
            scene_file = path
            choice = rng.random()
            if choice < 0.45:
                kind = "set"
                for _ in range(rng.randint(1, 3)):
                    key = rng.choice(leaves(parsed) + KEYS_EXTRA)
                    args += ["--set", "%s=%s" % (key, rng.choice(VALUES))]
            elif choice < 0.9:
                mutated, kind = mutate_text(text, rng, names)
                if rng.random() < 0.3:
                    mutated, _ = mutate_text(mutated, rng, names)
                scene_file = os.path.join(work, "case.yaml")
                with open(scene_file, "w", encoding="utf-8", errors="surrogateescape") as f:
                    f.write(mutated)
            else:
                kind = "args"
                args += rng.choice([["--set", "=1"], ["--set", "noequals"], ["--set"], ["--bag-ns", "bad name!"],
                                    ["--summary", "/nonexistent/x.yaml"], ["--out", "/nonexistent/x.csv"],
                                    ["--set", "analysis.type=static", "--set", "analysis.type=dynamic"],
                                    ["--frobnicate"], ["--bag", os.path.join(work, "b.bag"), "--bag-ns", "rel"]])
            csv_path = os.path.join(work, "out.csv")
            summary_path = os.path.join(work, "summary.yaml")
            for f in (csv_path, summary_path):
                if os.path.exists(f):
                    os.remove(f)
            cmd = [a.bin, scene_file] + args
            if "--out" not in args:
                cmd += ["--out", csv_path]
            if "--summary" not in args:
                cmd += ["--summary", summary_path]
            try:
                r = subprocess.run(cmd, capture_output=True, timeout=a.timeout)
                rc, out, err = r.returncode, r.stdout.decode(errors="replace"), r.stderr.decode(errors="replace")
            except subprocess.TimeoutExpired as e:
                rc, out, err = None, "", (e.stderr or b"").decode(errors="replace")
            read = lambda f: open(f, errors="replace").read() if os.path.exists(f) else ""
            cls = classify(rc, out, err, read(csv_path), read(summary_path))
            counts[cls] += 1
            by_kind[kind][cls] += 1
            if cls in ("unnamed", "non_finite", "long_message", "crash", "hang"):
                defects += 1
                d = os.path.join(out_dir, "%s_%04d" % (cls, case))
                os.makedirs(d, exist_ok=True)
                shutil.copy(scene_file, os.path.join(d, "scene.yaml"))
                with open(os.path.join(d, "README"), "w") as f:
                    f.write("class: %s (exit %s)\nscene: %s\nargs: %r\n\nstderr:\n%s\n" % (
                        cls, rc, path, args, err[:20000]))
                print("defect %s: case %d on %s, args %r" % (cls, case, os.path.basename(path),
                                                            [x[:80] for x in args[len(BASE):]]), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    total = sum(counts.values())
    print("fuzz_run: %d cases, seed %d: %s" % (total, a.seed, ", ".join(
        "%s %d" % (c, counts[c]) for c in ("refused", "bad_args", "ran", "stopped", "unnamed", "non_finite",
                                           "long_message", "crash", "hang"))))
    for kind in sorted(by_kind):
        print("  %-15s %s" % (kind, ", ".join("%s %d" % kv for kv in sorted(by_kind[kind].items()))))
    if defects:
        print("fuzz_run: %d defects saved in %s" % (defects, out_dir))
    return 1 if defects else 0


if __name__ == "__main__":
    sys.exit(main())
