"""The protocol-planning plot: expected hemisphere error against the number of samples."""

from __future__ import annotations

from kesbrdf.plotting._mpl import new_figure

__all__ = ["plot_plan", "figure_plan"]


def plot_plan(ax, result: dict):
    """Protocols as labelled points, the greedy recommendation as a path.

    Parameters
    ----------
    ax : matplotlib Axes
    result : dict
        :meth:`kesbrdf.measure.planning.PlanResult.to_dict`.
    """
    for name, p in result["protocols"].items():
        if p.get("over_budget"):
            continue
        ax.plot(p["n_samples"], p["median"], "o", color="C0")
        ax.annotate(name, (p["n_samples"], p["median"]), textcoords="offset points", xytext=(4, 4), fontsize=8)
    rec = result.get("recommendation") or []
    if rec:
        ax.plot([r["n_samples"] for r in rec], [r["median"] for r in rec], "s-", color="C3",
                label="greedy additions to the paper protocol")
        for r in rec[1:]:
            ax.annotate(f"+{r['add']}", (r["n_samples"], r["median"]), textcoords="offset points",
                        xytext=(4, -10), fontsize=7, color="C3")
        ax.legend(loc="upper right", fontsize=8)
    ax.axvline(result["budget"], color="0.6", ls=":", lw=1)
    ax.set_xlabel("samples measured")
    ax.set_ylabel("expected hemisphere NRMSE (median)")
    ax.set_ylim(bottom=0)
    ax.set_title(f"Protocol planning ({len(result['truths'])} truth(s), budget {result['budget']})", fontsize=10)
    return ax


def figure_plan(result: dict, figsize=(6.4, 4.2)):
    fig = new_figure(figsize=figsize)
    plot_plan(fig.add_subplot(1, 1, 1), result)
    return fig
