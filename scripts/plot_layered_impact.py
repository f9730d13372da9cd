#!/usr/bin/python3
"""The force-overlap curve of a layered strut's impact (docs/validation.md, "Layered struts").

usage: plot_layered_impact.py OUT.png      (in the devel or install space's environment)

config/scenes/impact.yaml (a strut dropped across a spring-held one, elastic contact) with rubber sleeves of
20 mm radius (E = 200 MPa, nu = 0.45) over steel cores of 8 mm: the cores meet at an overlap of 24 mm. The
drop is driven by gravity of 500 to 20000 m/s^2 (impact at about 7 to 45 m/s). Elastic contact (restitution 1):
every contact row lies on the law F = K z^3/2 + K_c (z - t)^3/2, drawn from the pair's constants.
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import active_tensegrity as at  # noqa: E402

LAYERED = {"materials.rubber.youngs_modulus": 2e8, "materials.rubber.poisson_ratio": 0.45,
           "materials.rubber.density": 1000.0, "struts.material": "rubber", "struts.core.radius": 0.008,
           "struts.core.material": "steel", "solver.dt": 1e-6, "analysis.output_interval": 0}


def main(out):
    fig, ax = plt.subplots(figsize=(7, 4.5))
    largest = 0.0
    for g in (500.0, 2000.0, 8000.0, 20000.0):
        # the 5 cm drop, then the contact and the rebound
        duration = np.sqrt(0.1 / g) + 0.006
        r = at.run("config/scenes/impact.yaml", dict(LAYERED, **{"gravity.vector": "[0, 0, -%g]" % g,
                                                                "analysis.duration": round(duration, 4)}))
        c = r.contacts  # columns: step, a, b, points, normal, penetration (12), rate, normal force (14), ...
        speed = np.sqrt(2.0 * g * 0.05)
        line, = ax.plot(c[:, 12] * 1e3, c[:, 14] / 1e3, ".", ms=2)
        top = np.argmax(c[:, 12])  # the largest overlap of this impact, marked
        ax.plot(c[top, 12] * 1e3, c[top, 14] / 1e3, "o", color=line.get_color(), ms=7,
                label="impact at %.0f m/s: %.1f mm (%s)" % (speed, c[top, 12] * 1e3, r.summary["status"]))
        largest = max(largest, c[:, 12].max())
        print("g = %g m/s^2: impact %.1f m/s, largest overlap %.2f mm, force %.0f kN" %
              (g, speed, c[:, 12].max() * 1e3, c[:, 14].max() / 1e3))
    # the law at a right crossing (the drop is one)
    e_sleeve = 1.0 / (2.0 * (1.0 - 0.45 ** 2) / 2e8)
    e_core = 1.0 / (2.0 * (1.0 - 0.3 ** 2) / 210e9)
    k, kc, t = 4.0 / 3.0 * e_sleeve * np.sqrt(0.02), 4.0 / 3.0 * e_core * np.sqrt(0.008), 0.024
    z = np.linspace(largest * 1e-3, largest * 1.02, 800)
    f = k * z ** 1.5 + kc * np.clip(z - t, 0.0, None) ** 1.5
    ax.plot(z * 1e3, f / 1e3, "k-", lw=0.8, label="K z^1.5 + K_c (z - t)^1.5")
    ax.axvline(t * 1e3, color="grey", ls="--", lw=0.8)
    ax.text(t * 1e3, 2e-2, " cores meet", color="grey", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylim(1e-2, None)
    ax.set_xlabel("overlap z (mm)")
    ax.set_ylabel("normal force (kN)")
    ax.set_title("layered struts: rubber sleeves over steel cores", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print("plot_layered_impact: wrote %s" % out)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
