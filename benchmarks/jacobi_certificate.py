"""The Wisdom–Holman splitting's exact certificate against the number of bodies.

Not a test: run it and read the table (wall seconds on this machine, with its load).

    python benchmarks/jacobi_certificate.py [--bodies 4 8 11 21]

For each N, in a fresh process: the exact Jacobi identities (:func:`methodgen.symbolic.nbody._jacobi_identities`:
canonical map, kinetic energy, Kepler masses; SymPy, no floating point) and the whole
``mg.wisdom_holman(scene, "saba3")`` (H compared with the ``[nbody]`` H, the identities, the
numerical certificate) for a star and N − 1 planets on a ring.  (A scene's H is text: at 21
bodies it is near the parser's 20,000-character limit; the identities alone take 0.2 s at 41.)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap

PROBE = textwrap.dedent(r"""
    import json, math, sys, time
    n = int(sys.argv[1]); path = sys.argv[2]
    kin = " + ".join(f"(px{b}**2 + py{b}**2 + pz{b}**2)/(2*m{b})" for b in range(n))
    pot = " ".join(f"- G*m{a}*m{b}/sqrt((x{a} - x{b})**2 + (y{a} - y{b})**2 + (z{a} - z{b})**2)"
                   for a in range(n) for b in range(a + 1, n))
    q = [f"{c}{b}" for b in range(n) for c in "xyz"]
    p = [f"p{c}{b}" for b in range(n) for c in "xyz"]
    Q, V = [0.0] * 3, [0.0] * 3
    for i in range(1, n):
        r, th = 1.0 + 0.5 * i, 2 * math.pi * i / (n - 1)
        Q += [r * math.cos(th), r * math.sin(th), 0.0]
        s = 1e-3 * math.sqrt(1.0 / r)
        V += [-s * math.sin(th), s * math.cos(th), 0.0]
    params = "\n".join(["G = 1.0", "m0 = 1.0"] + [f"m{b} = 1e-3" for b in range(1, n)])
    text = (f'name = "ring{n}"\ndescription = "a star and {n - 1} planets"\n[system]\nH = "{kin} {pot}"\n'
            f"q = {q}\np = {p}\n[params]\n{params}\n[nbody]\nG = \"G\"\n"
            f"masses = {[f'm{b}' for b in range(n)]}\n[run]\nmethod = [\"stormer-verlet\"]\nh = 0.01\nsteps = 10\ny0 = {Q + V}\n")
    with open(path, "w") as f:
        f.write(text.replace("'", '"'))
    import methodgen as mg
    from methodgen.symbolic import nbody
    scene = mg.load_scene(path)
    t = time.perf_counter(); ids = nbody._jacobi_identities(n); t_ids = time.perf_counter() - t
    nbody._jacobi_identities.cache_clear()
    t = time.perf_counter(); mg.wisdom_holman(scene, "saba3"); t_wh = time.perf_counter() - t
    print(json.dumps({"bodies": n, "identities_s": t_ids, "wisdom_holman_s": t_wh, "proved": all(ids.values())}))
""")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", type=int, nargs="+", default=[4, 8, 11, 21])
    a = ap.parse_args()
    print(f"{'bodies':>6} {'identities s':>13} {'wisdom_holman s':>16} proved")
    for n in a.bodies:
        with tempfile.TemporaryDirectory() as tmp:
            out = subprocess.run([sys.executable, "-c", PROBE, str(n), os.path.join(tmp, "ring.toml")],
                                 capture_output=True, text=True)
        if out.returncode:
            print(f"{n:>6} error: {out.stderr.strip().splitlines()[-1][:120]}")
            continue
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"{n:>6} {r['identities_s']:13.3f} {r['wisdom_holman_s']:16.2f} {r['proved']}", flush=True)
    load = os.getloadavg()
    print(f"machine: {os.cpu_count()} cores; load average {load[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
