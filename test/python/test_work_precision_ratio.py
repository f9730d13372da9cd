"""scripts/work_precision_ratio.py on hand-made work-precision CSVs: the ratio at equal error interpolates our
ladder in log-log, --front keeps only MuJoCo's undominated runs and names the worst ratio, and bad input is
refused with a message."""

import math
import os
import subprocess
import sys

SOURCE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCRIPT = os.path.join(SOURCE, "scripts", "work_precision_ratio.py")
HEADER = ("scheme,dt,tolerance,status,steps,newton_iterations,wall_time,position_error,height_error,force_error,"
          "peak_force_error,peak_time_error,impulse_error,peak_force,reference_peak_force")


def row(scheme, dt, wall, position, status="converged"):
    return "%s,%g,0,%s,100,200,%g,%g,0,0,0,0,%g,1,1" % (scheme, dt, status, wall, position, position / 10)


def run(tmp_path, rows, *args):
    path = tmp_path / "wp.csv"
    path.write_text("\n".join([HEADER] + rows) + "\n")
    return subprocess.run([sys.executable, SCRIPT, str(path)] + list(args), capture_output=True, text=True)


# our ladder: error 1e-3 at 0.01 s, 1e-5 at 0.04 s (time doubles per decade of error)
OURS = [row("adaptive_generalized_alpha", 0, 0.01, 1e-3), row("adaptive_generalized_alpha", 0, 0.04, 1e-5)]


def expected_time(err):
    f = (math.log(err) - math.log(1e-5)) / (math.log(1e-3) - math.log(1e-5))
    return math.exp(math.log(0.04) + f * (math.log(0.01) - math.log(0.04)))


def test_front_keeps_undominated_runs_and_names_the_worst_ratio(tmp_path):
    mujoco = [
        row("mujoco_euler", 1e-3, 0.02, 1e-4),     # on the front
        row("mujoco_implicit", 1e-3, 0.05, 1e-4),  # as accurate, slower: dominated
        row("mujoco_rk4", 5e-4, 0.2, 2e-5),        # more accurate, slower: on the front
        row("mujoco_euler", 1e-4, 0.3, 5e-5),      # slower and less accurate than rk4's: dominated
        row("mujoco_euler", 2e-3, 0.01, 1e-2, status="diverged"),  # not converged: ignored
    ]
    out = run(tmp_path, OURS + mujoco, "--front")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    front = [l for l in lines if l.startswith("| mujoco_")]
    assert [l.split(" | ")[0] for l in front] == ["| mujoco_euler dt 0.001", "| mujoco_rk4 dt 0.0005"]
    ratios = [float(l.rstrip(" |").split(" | ")[-1]) for l in front]
    assert abs(ratios[0] - expected_time(1e-4) / 0.02) < 0.01
    assert abs(ratios[1] - expected_time(2e-5) / 0.2) < 0.01
    assert lines[-1] == "worst ratio: %.2f (mujoco_euler dt 0.001)" % (expected_time(1e-4) / 0.02)


def test_front_says_when_no_scheme_reaches_the_error(tmp_path):
    out = run(tmp_path, OURS + [row("mujoco_euler", 1e-4, 0.1, 1e-7)], "--front")
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[-1].startswith("worst ratio: none")


def test_the_metric_argument_chooses_the_column(tmp_path):
    out = run(tmp_path, OURS + [row("mujoco_euler", 1e-3, 0.02, 1e-4)], "impulse_error", "--front")
    assert out.returncode == 0, out.stderr
    # the impulse errors are a tenth of the position errors in these rows: the same ratio
    assert "| impulse_error |" in out.stdout
    assert out.stdout.splitlines()[-1] == "worst ratio: %.2f (mujoco_euler dt 0.001)" % (expected_time(1e-4) / 0.02)


def test_bad_arguments_are_refused(tmp_path):
    unknown = run(tmp_path, OURS, "no_such_metric")
    assert unknown.returncode != 0 and "no column 'no_such_metric'" in unknown.stderr
    option = run(tmp_path, OURS, "--fronts")
    assert option.returncode != 0 and "work_precision_ratio.py FILE.csv" in option.stderr
