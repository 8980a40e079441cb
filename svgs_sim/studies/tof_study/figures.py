"""The ToF study's figures: the stability series, the mechanisms, the accuracy-versus-distance sweep
(the paper's Fig. 14).

Part of :mod:`svgs_sim.studies.tof_study`.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.sim.tof_stability import COLUMNS

from .design import PAPER_RANGES_M, SWEEP_SCHEMES, PAPER_ACCURACY, PAPER_FIG14_Z_MM


def plot_series(path, runs, sums) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(6, 2, figsize=(11, 11), sharex="col")
    for j, r in enumerate(PAPER_RANGES_M):
        run, s = runs[r], sums[r]
        k = np.array([row["frame"] for row in run["frame_rows"] if row["ok"]])
        for i, c in enumerate(COLUMNS):
            ax = axes[i, j]
            ax.plot(k, run["cols"][:, i], lw=0.5)
            for n, (tab, st) in enumerate(sorted(s["paper"].items())):
                if "fluctuation" in st:
                    h = 0.5 * st["fluctuation"][c]
                    ax.axhspan(s["average"][c] - h, s["average"][c] + h, color=f"C{n + 1}", alpha=0.15,
                               label=f"paper T{tab} range")
            ax.set_ylabel(c, fontsize=8)
            if i == 0:
                ax.set_title(f"{r} m: {s['solved']}/{s['frames']} solved")
                ax.legend(fontsize=6, loc="upper right")
        axes[-1, j].set_xlabel("frame")
    fig.suptitle("Stability runs (bands: the paper's fluctuation ranges, drawn about our mean)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_mechanisms(path, sums, var_rows) -> None:
    """Fluctuation / paper (log colour, 0.5-2 is the band) per run and component, at both ranges."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    fig, axes = plt.subplots(1, 2, figsize=(15, 6.5), gridspec_kw={"wspace": 0.75})
    for ax, r, tab in zip(axes, PAPER_RANGES_M, ("3", "2")):
        labels = ["baseline"] + [v["label"] for v in var_rows if v["range_m"] == r]
        rows = [sums[r]] + [v["summary"] for v in var_rows if v["range_m"] == r]
        M = np.array([[s["ratio_to_paper"].get(tab, {}).get(c) or np.nan for c in COLUMNS] for s in rows], float)
        im = ax.imshow(M, cmap="RdBu_r", norm=LogNorm(vmin=0.01, vmax=100), aspect="auto")
        for (i, j), v in np.ndenumerate(M):
            ok = 0.5 <= v <= 2
            ax.text(j, i, "nan" if not np.isfinite(v) else f"{v:.2g}", ha="center", va="center", fontsize=7,
                    fontweight="bold" if ok else "normal")
        ax.set_xticks(range(6), COLUMNS, rotation=30, fontsize=8)
        ax.set_yticks(range(len(labels)), labels, fontsize=7)
        ax.set_title(f"{r} m: fluctuation / paper Table {tab} (bold: within 2x)", fontsize=9)
    fig.colorbar(im, ax=axes, fraction=0.025)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def plot_sweep(path, sweep) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.3))
    for k, (scheme, _) in enumerate(SWEEP_SCHEMES):
        rows = [s for s in sweep if s["scheme"] == scheme]
        r = np.array([s["range_m"] for s in rows])
        ls = ("-", "--", ":")[k]
        for j, c in enumerate(COLUMNS[:3]):
            axes[0].plot(r, [s["rms"][c] if s["rms"] else np.nan for s in rows], "o" + ls, ms=3,
                         color=f"C{j}", label=f"{c} ({scheme})")
        for j, c in enumerate(COLUMNS[3:]):
            axes[1].plot(r, [s["rms"][c] if s["rms"] else np.nan for s in rows], "o" + ls, ms=3,
                         color=f"C{j + 3}", label=f"{c} ({scheme})")
    axes[0].axhline(PAPER_ACCURACY["mm"], color="k", ls=":", lw=0.8, label="paper: 2 mm")
    axes[1].axhline(PAPER_ACCURACY["deg"], color="k", ls=":", lw=0.8, label="paper: 0.13 deg")
    axes[0].plot([5, 10], [PAPER_FIG14_Z_MM] * 2, color="k", lw=2, alpha=0.4, label="paper: z 2.5 mm beyond 5 m")
    for ax, unit in zip(axes, ("mm", "deg")):
        ax.set_xlabel("range, m")
        ax.set_ylabel(f"single-frame RMS error, {unit}")
        ax.set_yscale("log")
        ax.legend(fontsize=6, ncol=2)
    fig.suptitle("Accuracy against distance (the paper's Fig. 14), target head-on: solid = the paper's literal "
                 "line-of-sight iteration (default), dashed = its converged optimum, dotted = depths blended in", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
