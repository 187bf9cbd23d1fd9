"""The protocol-planning plot: expected hemisphere error against the number of samples.

No text is drawn beside the points: protocols score alike more often than not (every
superset of the paper protocol that the fit does not use scores as the paper protocol,
docs/planning.md), so their points coincide and labels written next to them collide.
Each protocol gets its own marker instead, each greedy step its number as marker, and
the names and numbers go into a legend table beside the axes, one row each.
"""

from __future__ import annotations

from kesbrdf.plotting._mpl import new_figure

__all__ = ["plot_plan", "figure_plan"]

#: Protocol markers, unfilled so that coinciding points stay visible one inside another.
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "h", "p", "*")
#: Marker sizes (points), largest first, for the same reason.
SIZES = (13, 11, 9.5, 8, 7, 6, 5, 4.5, 4, 3.5, 3, 3)


def _protocol_label(name: str, p: dict) -> str:
    if p.get("over_budget"):
        return f"{name}: {p['n_samples']} samples, over budget (not scored)"
    unused = p["n_samples"] - p.get("rows_used", p["n_samples"])
    note = f", {unused} unused by the fit" if unused > 0 else ""
    return f"{name}: {p['n_samples']} samples, {p['median']:.3f}{note}"


def plot_plan(ax, result: dict):
    """Protocols as points, the greedy recommendation as a numbered path, names in a legend.

    Parameters
    ----------
    ax : matplotlib Axes
    result : dict
        :meth:`kesbrdf.measure.planning.PlanResult.to_dict`.
    """
    k = 0
    for name, p in result["protocols"].items():
        label = _protocol_label(name, p)
        if p.get("over_budget"):
            ax.plot([], [], "x", color="0.6", label=label)
            continue
        ax.plot(p["n_samples"], p["median"], MARKERS[k % len(MARKERS)], ms=SIZES[min(k, len(SIZES) - 1)],
                mfc="none", mew=1.3, color=f"C{k % 10}", label=label, ls="none")
        k += 1
    rec = result.get("recommendation") or []
    if rec:
        ax.plot([r["n_samples"] for r in rec], [r["median"] for r in rec], "-", color="C3", lw=1.2, alpha=0.7,
                label="greedy additions to the paper protocol:")
        for step, r in enumerate(rec):
            what = ", ".join(r["groups"]) if r["add"] is None else f"+{r['add']}"
            ax.plot(r["n_samples"], r["median"], marker=f"${step}$", ms=7, color="C3", ls="none",
                    label=f"  {step}: {what}: {r['n_samples']} samples, {r['median']:.3f}")
    ax.axvline(result["budget"], color="0.6", ls=":", lw=1, label=f"budget: {result['budget']} samples")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7, frameon=False, borderaxespad=0.0,
              title="protocol: samples, expected NRMSE", title_fontsize=7, alignment="left")
    ax.set_xlabel("samples measured")
    ax.set_ylabel("expected hemisphere NRMSE (median)")
    scores = [p["median"] for p in result["protocols"].values() if not p.get("over_budget")]
    scores += [r["median"] for r in rec]
    ax.set_ylim(0, 1.12 * max(scores) if scores and max(scores) > 0 else None)  # room above the top markers
    ax.set_title(f"Protocol planning ({len(result['truths'])} truth(s), budget {result['budget']})", fontsize=10)
    return ax


def figure_plan(result: dict, figsize=(9.0, 4.2)):
    fig = new_figure(figsize=figsize)
    plot_plan(fig.add_subplot(1, 1, 1), result)
    return fig
