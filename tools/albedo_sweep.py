"""The sun study with the Earth behind the target at three albedos (issue 38 item 3): 0.05 open
ocean, 0.3 the Bond albedo, 0.8 a bright cloud deck (docs/orbit.md). Each albedo is one
``svgs sun-study`` run (its own folder, resumable); this tool runs them and writes the table.

Usage::

    python tools/albedo_sweep.py --camera galaxy-nexus --out docs/reports/sun-study-albedo-galaxy-nexus \\
        [--earth-deg=0,-90] [--albedos 0.05,0.3,0.8] [--ranges 5,10] [--sun-azimuths-deg 0,180] \\
        [--sun-elevations-deg=-45,-15,15,45] [--trials 2] [--processes 2]

writes ``OUT/albedo-<a>/`` (the studies) and ``OUT/README.md`` (solved and wrong locks per albedo,
range and sun elevation; the Earth's direction ``--earth-deg=0,-90`` puts it straight behind the
target, filling the field: the R-bar from above). A sun below ~-20 deg elevation is then behind the
Earth (eclipse).
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--camera", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--earth-deg", default="0,-90")
    ap.add_argument("--albedos", default="0.05,0.3,0.8")
    ap.add_argument("--ranges", default="5,10")
    ap.add_argument("--sun-azimuths-deg", default="0,180")
    ap.add_argument("--sun-elevations-deg", default="-45,-15,15,45")
    ap.add_argument("--trials", default="2")
    ap.add_argument("--processes", default="2")
    a = ap.parse_args(argv)
    out = Path(a.out)
    runs = {}
    for albedo in (float(x) for x in a.albedos.split(",")):
        folder = out / f"albedo-{albedo:g}"
        cmd = [sys.executable, "-m", "svgs_sim.cli.main", "sun-study", "--camera", a.camera, f"--ranges={a.ranges}",
               f"--sun-azimuths-deg={a.sun_azimuths_deg}", f"--sun-elevations-deg={a.sun_elevations_deg}",
               "--trials", a.trials, f"--earth-deg={a.earth_deg}", "--earth-albedo", f"{albedo:g}",
               "--processes", a.processes, "--no-progress", "--json", "--out", str(folder)]
        print(" ".join(shlex.quote(c) for c in cmd[2:]), file=sys.stderr, flush=True)
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            raise SystemExit(f"albedo {albedo:g}: exit {p.returncode}\n{p.stderr[-2000:]}")
        runs[albedo] = json.loads(p.stdout)
    ranges = sorted({c["range_m"] for s in runs.values() for c in s["cells"]})
    els = sorted({c["sun_elevation_deg"] for s in runs.values() for c in s["cells"]})
    lines = [f"# {a.camera} on orbit with the Earth behind the target, three albedos", "",
             "Made by (each albedo's folder is a `svgs sun-study` run; a rerun resumes them):", "",
             "    python tools/albedo_sweep.py " + " ".join(shlex.quote(x) for x in (argv or sys.argv[1:])), "",
             f"The Earth toward {a.earth_deg} deg in the target frame (straight behind the target: it fills the "
             "field), 400 km; sun azimuths " f"{a.sun_azimuths_deg} deg, {a.trials} trials a cell. Cells: solved / "
             "wrong locks / trials, summed over the azimuths.", "",
             "| range, m | sun elevation, deg | " + " | ".join(f"albedo {x:g}" for x in runs) + " |",
             "|---|---|" + "---|" * len(runs)]
    for r in ranges:
        for el in els:
            row = []
            for s in runs.values():
                cs = [c for c in s["cells"] if c["range_m"] == r and c["sun_elevation_deg"] == el]
                row.append(f"{sum(c['solved'] for c in cs)} / {sum(c['wrong_lock'] for c in cs)} / "
                           f"{sum(c['trials'] for c in cs)}")
            lines.append(f"| {r:g} | {el:g} | " + " | ".join(row) + " |")
    tot = {x: (sum(c["solved"] for c in s["cells"]), sum(c["wrong_lock"] for c in s["cells"]),
               sum(c["trials"] for c in s["cells"])) for x, s in runs.items()}
    lines += ["", "All cells: " + "; ".join(f"albedo {x:g}: {v[0]} solved, {v[1]} wrong locks of {v[2]}"
                                             for x, v in tot.items()) + ".", ""]
    (out / "README.md").write_text("\n".join(lines))
    (out / "summary.json").write_text(json.dumps({f"{x:g}": {"solved": v[0], "wrong_lock": v[1], "trials": v[2]}
                                                  for x, v in tot.items()}, indent=1) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
