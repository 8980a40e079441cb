"""Write the shipped 3U CubeSat body (:mod:`svgs_sim.render.cubesat`, what ``svgs render --body 3u``
renders) as ``svgs_sim/assets/bodies/cubesat-3u.obj`` (an ``o`` object a part) and
``cubesat-3u.toml`` (each part's surface): to look at, or to start a mesh body of one's own from.

Usage::

    python tools/make_3u_body.py          # rewrites the two files (deterministic)

trimesh 5.2 does not keep the object names of a multi-part ``.obj`` (it names every part after
the first), so ``--body cubesat-3u.obj --body-materials cubesat-3u.toml`` cannot map them; give
``--body 3u`` for the shipped model.
"""

from __future__ import annotations

from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "svgs_sim" / "assets" / "bodies"


def write(out_dir: Path = OUT) -> tuple:
    from svgs_sim.base.profiles import load_pattern
    from svgs_sim.render.cubesat import SURFACES, parts
    from svgs_sim.render.geometry import Reflector, SceneOptions, build_target

    pat = load_pattern("svgs-3u")
    info = build_target(pat, Reflector.resolve(None, pat), SceneOptions.resolve({"body": "3u"})).info
    P = parts(float(info["face_z_m"]), info.get("boom_3u"), info["body_centre_xy_m"])
    lines = ["# 3U CubeSat body for the svgs-3u pattern, metres, target frame: written by tools/make_3u_body.py"]
    n = 0
    for name, tris in P.items():
        lines.append(f"o {name}")
        for t in tris:
            for v in t:
                lines.append("v " + " ".join(f"{c:.6f}" for c in v))
            lines.append(f"f {n + 1} {n + 2} {n + 3}")
            n += 3
    out_dir.mkdir(parents=True, exist_ok=True)
    obj = out_dir / "cubesat-3u.obj"
    obj.write_text("\n".join(lines) + "\n")
    toml = out_dir / "cubesat-3u.toml"
    toml.write_text("# The surfaces of cubesat-3u.obj's parts (svgs_sim/assets/materials/surfaces.toml): written by "
                    "tools/make_3u_body.py\n" + "".join(f'{k} = "{v}"\n' for k, v in SURFACES.items() if k in P))
    return obj, toml


if __name__ == "__main__":
    for p in write():
        print(f"wrote {p}")
