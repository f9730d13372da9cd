#!/usr/bin/env python3
"""Random-request fuzzer of the folding planner: plans with random requests on the shipped scenes, each in a
process of its own, and sorts every outcome into one class.

  fuzz_plan.py [--cases N] [--seed S] [--scenes DIR] [--timeout SEC]

A request draws a scene with actuators, a subset of them, a planner by name (the offered ones, FMT and BFMT,
which are refused, and an unknown name), a goal (a height, or target values; one in ten out of reach), contact
or clearance limits, sometimes a blend tolerance or the dynamic verification, a seed and a deadline of
0.05-0.5 s. Needs the package's Python module (a built workspace's devel space on PYTHONPATH).

Classes (the first two are fine, the rest are defects):
  planned      an answer with a known status; trajectory values finite
  refused      ValueError, or status invalid_request, with a message
  bad_answer   an unknown status, a non-finite trajectory value, a refusal without a message
  crash        killed by a signal, or an uncaught exception
  hang         still running after --timeout seconds
Exit status: 0 without defects, 1 with any (each printed with the request that reproduces it).
"""
import argparse
import collections
import json
import math
import os
import random
import subprocess
import sys

STATUSES = {"unknown", "invalid_start", "invalid_goal", "unrecognized_goal_type", "timeout",
            "approximate_solution", "exact_solution", "crash", "abort", "invalid_request"}


def one(scene, request):
    """Plans one request (in the worker process) and prints its class and a short reason as JSON."""
    import active_tensegrity as at
    model = at.load(scene)
    try:
        plan = at.plan_folding(model, **request)
    except ValueError as e:
        print(json.dumps({"class": "refused", "why": str(e)[:200]}))
        return
    status = plan.get("status")
    if status not in STATUSES:
        print(json.dumps({"class": "bad_answer", "why": "status %r" % status}))
        return
    if status == "invalid_request":
        ok = bool(plan.get("message"))
        print(json.dumps({"class": "refused" if ok else "bad_answer", "why": plan.get("message", "")[:200]}))
        return
    values = [v for point in plan.get("positions", []) for v in point]
    if not all(math.isfinite(v) for v in values):
        print(json.dumps({"class": "bad_answer", "why": "non-finite trajectory value"}))
        return
    print(json.dumps({"class": "planned", "why": status}))


def draw(rng, scenes, planners):
    name = rng.choice(sorted(scenes))
    actuators = scenes[name]
    chosen = rng.sample(actuators, rng.randint(1, len(actuators)))
    request = {"actuators": chosen, "planner": rng.choice(planners), "seed": rng.randint(0, 2**32 - 1),
               "time_limit": rng.choice([0.05, 0.1, 0.2, 0.5])}
    odd = rng.random() < 0.1  # a goal outside what the scene can take
    if rng.random() < 0.5:
        request["target_height"] = rng.choice([-0.5, 1e9]) if odd else rng.uniform(0.0, 2.5)
    else:
        request["target_values"] = [rng.uniform(-0.2, 2.0) if odd else rng.uniform(0.0, 0.7) for _ in chosen]
    if rng.random() < 0.5:
        request["allow_contact"] = True
        request["max_contact_force"] = rng.choice([1.0, 400.0, 1e6])
    else:
        request["min_clearance"] = rng.choice([0.0, 0.005, 0.05])
    if rng.random() < 0.2:
        request["blend_tolerance"] = rng.choice([0.01, 0.1])
    if rng.random() < 0.1:
        request["verify_dynamics"] = True
    return name, request


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    here = os.path.dirname(os.path.abspath(__file__))
    parser.add_argument("--cases", type=int, default=60)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--scenes", default=os.path.join(here, "..", "config", "scenes"))
    parser.add_argument("--timeout", type=float, default=120.0)
    parser.add_argument("--one", nargs=2, metavar=("SCENE", "REQUEST_JSON"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        one(args.one[0], json.loads(args.one[1]))
        return 0

    import active_tensegrity as at
    scenes = {}
    for name in sorted(os.listdir(args.scenes)):
        if name.endswith(".yaml"):
            path = os.path.join(args.scenes, name)
            try:
                actuators = at.load(path).actuators
            except Exception:  # a scene the loader refuses has nothing to plan
                continue
            if actuators:
                scenes[path] = list(actuators)
    planners = at.planners() + ["FMT", "BFMT", "Magic"]
    rng = random.Random(args.seed)
    counts = collections.Counter()
    defects = 0
    for case in range(args.cases):
        scene, request = draw(rng, scenes, planners)
        command = [sys.executable, os.path.abspath(__file__), "--one", scene, json.dumps(request)]
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=args.timeout)
            if done.returncode != 0:
                kind, why = "crash", "exit status %d: %s" % (done.returncode, done.stderr.strip()[-300:])
            else:
                answer = json.loads(done.stdout.strip().splitlines()[-1])
                kind, why = answer["class"], answer["why"]
        except subprocess.TimeoutExpired:
            kind, why = "hang", "still running after %g s" % args.timeout
        counts[kind] += 1
        if kind not in ("planned", "refused"):
            defects += 1
            print("fuzz_plan: %s: %s\n  reproduce: %s --one %s '%s'"
                  % (kind, why, os.path.abspath(__file__), scene, json.dumps(request)), file=sys.stderr)
    print("fuzz_plan: %d requests on %d scenes: %s" % (args.cases, len(scenes),
                                                         ", ".join("%s %d" % kv for kv in sorted(counts.items()))))
    return 1 if defects else 0


if __name__ == "__main__":
    sys.exit(main())
