"""Study files and study command lines, mutated at random (a fixed seed): reading a study file either gives a
study or raises StudyError, and the command ends with its status (0, 1 with one line naming the key, 2 for
arguments it does not take), never with a traceback. The command runs with --check (it reads the study and runs
nothing); a few cases run it as a program."""

import contextlib
import copy
import datetime
import io
import os
import random
import subprocess
import sys
import tempfile

import pytest
import yaml

from active_tensegrity import study

SOURCE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENE = os.path.join(SOURCE, "config", "scenes", "prism_pinned.yaml")

SEED = """scene: %s
set: {analysis.steps: 5, solver.newton_tolerance: 1.0e-8}
grid:
  analysis.max_actuation: [0.0005, 0.001]
  struts.radius: [0.01, 0.02]
points:
  - {analysis.max_actuation: 0.0015, struts.radius: 0.01}
  - {analysis.max_actuation: 0.002, struts.radius: 0.015}
collect:
  summary: [status, message, newton_iterations, peaks.max_cable_stress.value]
  peaks: {max_cable_stress: max, height: min}
  final: [height, actuation]
save:
  name: "r{struts.radius}_h{analysis.max_actuation}"
  files: [table, summary]
plots:
  - {x: analysis.max_actuation, y: [min_height], by: struts.radius, file: height.png, logx: false}
""" % SCENE

# pieces a mutation puts in: YAML syntax, odd scalars and keys, tags, anchors, bytes that are not UTF-8
PIECES = ["{", "}", "[", "]", ":", ": ", "- ", ",", "&a ", "*a", "*b", "!!binary aGk=", "!!set {a, b}",
          "!!python/tuple", "~", "null", ".nan", "-.inf", "1e999", "0x10", "2020-01-01", "2020-01-01T00:00:00",
          "true", "'", '"',
          "\"\\ud800\"", "\\x00", "\t", "\n", "\n  ", "? [a, b]\n: 1\n", "1: ", "0: x\n", "-1", "3.5", "[1, 2]",
          "{a: 1}", "%YAML 1.1\n", "---\n", "...\n", "#", "|\n  x\n", ">\n  y\n", "max", "min", "summary",
          "peaks", "status", "table", "members", "{x}", "{struts.radius}", "/", "..", "height.png", "x.txt",
          "[" * 300 + "]" * 300, "[" * 5000, "{a: " * 80 + "1" + "}" * 80]
BYTES = [b"\xff", b"\xfe\xff", b"\xc3", b"\x00", b"\xed\xa0\x80", b"\xe2\x82"]


def mutate(rng, text):
    data = text.encode()
    for _ in range(rng.randint(1, 4)):
        kind = rng.randrange(7)
        at = rng.randrange(len(data) + 1)
        if kind == 0:  # a piece put in
            data = data[:at] + rng.choice(PIECES).encode() + data[at:]
        elif kind == 1:  # a piece in place of a stretch
            data = data[:at] + rng.choice(PIECES).encode() + data[at + rng.randint(1, 12):]
        elif kind == 2:  # bytes cut
            data = data[:at] + data[at + rng.randint(1, 30):]
        elif kind == 3:  # a byte that is not UTF-8
            data = data[:at] + rng.choice(BYTES) + data[at:]
        elif kind == 4:  # lines shuffled, doubled or dropped
            lines = data.split(b"\n")
            i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
            choice = rng.randrange(3)
            if choice == 0:
                lines[i], lines[j] = lines[j], lines[i]
            elif choice == 1:
                lines.insert(i, lines[j])
            else:
                del lines[i]
            data = b"\n".join(lines)
        elif kind == 5:  # a byte changed
            if data:
                at = min(at, len(data) - 1)
                data = data[:at] + bytes([rng.randrange(256)]) + data[at + 1:]
        else:  # the end cut off
            data = data[:at]
    return data


def deep(levels):
    value = 1
    for _ in range(levels):
        value = [value]
    return value


# values a structural mutation puts in place of one of the study's values, or under a new key
VALUES = [0, -1, 7, 1.5, 1e-300, float("nan"), float("inf"), "", "x", "max", "min", "status", "message", "peaks",
          "peaks.max_cable_stress.value", "peaks.max_cable_stress", "time_breakdown.solve.seconds", "final.height",
          "height", "max_cable_stress", "no_such_column", "table", "members", "r{struts.radius}", "{nope}", "a/b",
          "..", "plot.png", "plot.gif", None, True, False, [], {}, [1, [2, [3]]], {"a": 1}, {1: "max"}, {"x": "max"},
          {None: 1}, {True: "min"}, {1.5: [1]}, datetime.date(2020, 1, 1), b"binary", {"a", "b"}, "\u00e9\u00df",
          "x" * 5000, list(range(400)), deep(70), deep(40), ["a", {"b": ["c", None]}], [[0.001, 0.002]],
          [0.001] * 3, ["max"], [{}]]
KEYS = VALUES[:30] + [1, 2.5, None, False, "scene", "set", "grid", "points", "collect", "save", "plots", "summary",
                      "peaks", "final", "name", "files", "x", "y", "by", "file", "title", "logx", "analysis.steps"]


def mutate_tree(rng, text):
    """The study's YAML with one to three of its values replaced, dropped or given a sibling, dumped again."""
    doc = copy.deepcopy(yaml.safe_load(text))
    for _ in range(rng.randint(1, 3)):
        places = []  # (container, key or index)
        stack = [doc]
        while stack:
            node = stack.pop()
            items = list(node.items()) if isinstance(node, dict) else \
                list(enumerate(node)) if isinstance(node, list) else []
            for k, v in items:
                places.append((node, k))
                if isinstance(v, (dict, list)):
                    stack.append(v)
        if not places:
            break
        node, key = rng.choice(places)
        action = rng.randrange(4)
        if action == 0 and isinstance(node, dict):
            del node[key]
        elif action == 1 and isinstance(node, dict):
            try:
                node[rng.choice(KEYS)] = copy.deepcopy(rng.choice(VALUES))
            except TypeError:  # an unhashable key
                pass
        else:
            node[key] = copy.deepcopy(rng.choice(VALUES))
    return yaml.safe_dump(doc, allow_unicode=True).encode()


def test_mutated_study_files_are_read_or_refused_with_a_study_error():
    rng = random.Random(20240611)
    outcomes = {"read": 0, "refused": 0}
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "fuzz.yaml")
        for n in range(2000):
            data = mutate(rng, SEED) if n % 2 else mutate_tree(rng, SEED)
            with open(path, "wb") as f:
                f.write(data)
            try:
                got = study.read_study(path)
            except study.StudyError as e:
                outcomes["refused"] += 1
                message = str(e)
                assert message and len(message) < 3000, (data, message)
                continue
            except BaseException as e:  # anything else is a bug: show the file that made it
                pytest.fail("mutation %d raised %s: %s\nfile: %r" % (n, type(e).__name__, e, data))
            outcomes["read"] += 1
            assert got["points"] and all(isinstance(k, str) for p in got["points"] for k in p)
            assert all(isinstance(c, str) for c in study._columns(got))
            for p in got["points"]:  # what the points give to the loader and to the kept results' names
                study.point_id(p)
                for v in p.values():
                    study.value_text(v)
    # the mutations reach both sides
    assert outcomes["read"] > 100 and outcomes["refused"] > 1000, outcomes


def main(argv):
    """The command in this process: its status, and what it wrote to stderr."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = study.main(argv)
        except SystemExit as e:
            code = e.code
    return code, err.getvalue()


def test_odd_command_lines_end_with_a_status_and_one_line():
    rng = random.Random(7)
    with tempfile.TemporaryDirectory() as tmp:
        good = os.path.join(tmp, "good.yaml")
        with open(good, "w") as f:
            f.write(SEED)
        bad = os.path.join(tmp, "bad.yaml")
        files = [good, bad, tmp, os.path.join(tmp, "missing.yaml"), "", "-", "\x00", "good.yaml\udcff"]
        options = [["--scheduler", v] for v in ("tcp://127.0.0.1:8786", "localhost:8786", "foo", "tcp://",
                                                  "http://h:1", "tcp://h:0", "tcp://h:99999", "", "tcp://[::1]:1",
                                                  "inproc://x", " tcp://h:1", "tcp://h:1/x")]
        options += [["--workers", v] for v in ("1", "2", "0", "-3", "257", "1e3", "x", "", "99999999999999999999")]
        options += [["--set", v] for v in ("analysis.steps=3", "a", "=1", "a=", "a=[", "a={b: 1", "a=" + "[" * 3000,
                                             "a=2020-01-01", "a=!!binary aGk=", "a=\"\\ud800\"", "1=2", "a=b=c",
                                             "a=.nan", "a=~")]
        options += [["--out", v] for v in (os.path.join(tmp, "out"), good, "", "\x00")]
        options += [["--no-progress"], ["--unknown"], ["--scheduler"], ["--workers"], ["--set"], ["-h"]]
        for n in range(300):
            with open(bad, "wb") as f:
                f.write(mutate(rng, SEED) if n % 2 else mutate_tree(rng, SEED))
            argv = [rng.choice(files)] if rng.random() < 0.95 else []
            for _ in range(rng.randint(0, 3)):
                argv += rng.choice(options)
            rng.shuffle(argv) if rng.random() < 0.1 else None
            argv.append("--check")
            code, err = main(argv)
            assert code in (0, 1, 2), (argv, code, err)
            assert "Traceback" not in err, (argv, err)
            if code == 1:
                assert err.startswith("study: ") and err.count("\n") == 1, (argv, err)
            elif code == 2 and "-h" not in argv:
                assert err.strip().splitlines()[-1].startswith("python3 -m active_tensegrity.study: error: "), \
                    (argv, err)


def run(args, **kwargs):
    return subprocess.run([sys.executable, "-m", "active_tensegrity.study"] + args, capture_output=True, text=True,
                          timeout=120, **kwargs)


def test_the_command_refuses_what_it_cannot_read_without_a_traceback():
    with tempfile.TemporaryDirectory() as tmp:
        cases = [
            (b"scene: %s\ngrid: {analysis.steps: [1]}\n# \xff\xfe\n" % SCENE.encode(),
             "not UTF-8 text (byte 0xff at offset"),
            (b"1: 2\nscene: %s\n" % SCENE.encode(), "unknown keys [1]"),
            (b"scene: %s\ngrid: {2: [1]}\n" % SCENE.encode(), "grid: the key 2 is not an override key"),
            (b"scene: %s\npoints: [{analysis.steps: 1, 3: 4}]\n" % SCENE.encode(), "points[0]: the key 3"),
            (b"scene: %s\ngrid: {analysis.steps: %s}\n" % (SCENE.encode(), b"[" * 10000 + b"]" * 10000),
             "nested deeper than 64 levels"),
            (b"scene: %s\ngrid: {analysis.steps: [1]}\ncollect: {summary: [peaks]}\n" % SCENE.encode(),
             "collect.summary: 'peaks' is a mapping"),
            (b"scene: %s\ngrid: {analysis.steps: [1]}\ncollect: {final: {height: 1}}\n" % SCENE.encode(),
             "collect.final"),
            (b"scene: %s\ngrid: {a: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10], b: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10], "
             b"c: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10], d: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10], "
             b"e: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10], f: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]}\n" % SCENE.encode(),
             "1000000 points (grid and points): more than 100000"),
        ]
        for data, words in cases:
            path = os.path.join(tmp, "bad.yaml")
            with open(path, "wb") as f:
                f.write(data)
            done = run([path, "--no-progress"])
            assert done.returncode == 1 and words in done.stderr, (data[:200], done.stderr)
            assert "Traceback" not in done.stderr and done.stderr.count("\n") == 1, done.stderr
        good = os.path.join(tmp, "good.yaml")
        with open(good, "w") as f:
            f.write(SEED)
        for args, words in ((["--scheduler", "foo:bar"], "--scheduler: expected a scheduler's address"),
                            (["--scheduler", "tcp://h:99999"], "--scheduler: expected"),
                            (["--workers", "0"], "--workers: 1 to 256, got 0"),
                            (["--scheduler", "tcp://127.0.0.1:1", "--workers", "2"], "--workers: for a local")):
            done = run([good, "--no-progress"] + args)
            assert done.returncode == 2 and words in done.stderr, (args, done.stderr)
            assert "Traceback" not in done.stderr
        # an address of the right form where no scheduler listens: status 1, the address named
        env = dict(os.environ, DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="1s")
        done = run([good, "--no-progress", "--scheduler", "tcp://127.0.0.1:1", "--out", os.path.join(tmp, "o")],
                   env=env)
        assert done.returncode == 1 and "--scheduler tcp://127.0.0.1:1: cannot connect" in done.stderr, done.stderr
        assert "Traceback" not in done.stderr and done.stderr.count("\n") == 1
        # --check reads and runs nothing
        done = run([good, "--check", "--out", os.path.join(tmp, "checked")])
        assert done.returncode == 0 and "6 points" in done.stdout and "min_height_t" in done.stdout, done.stdout
        assert not os.path.exists(os.path.join(tmp, "checked")) and not os.path.exists(os.path.join(tmp, "good"))
