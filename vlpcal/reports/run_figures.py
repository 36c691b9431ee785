"""A run's figures: the demo's comparison of pipelines, and a locate's or a track's fixes
over time and on the plan."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from .figures import _pyplot, error_cdf, save_figure


def demo_figure(path, site, truth, fixes_of: dict, cameras, shown: tuple) -> None:
    """The robot's path seen from above with the fixes of the ``shown`` pipelines, and the
    error CDF of every pipeline (``fixes_of``: label → FixBatch on the same frames)."""
    plt = _pyplot()
    fig, (top, cdf) = plt.subplots(1, 2, figsize=(13, 5), constrained_layout=True)
    room = np.array(list(site.room) + [site.room[0]])
    top.plot(room[:, 0], room[:, 1], "k-", lw=1)
    for c in cameras:
        top.plot(*c.position[:2], "c^", ms=8, mec="k")
        top.annotate(c.id, c.position[:2], fontsize=7, xytext=(4, 4), textcoords="offset points")
    top.plot(truth[:, 0], truth[:, 1], "-", color="0.6", lw=1.5, label="the LED's true path")
    for label, style in zip(shown, ("x", ".")):
        X = fixes_of[label].X
        top.plot(X[:, 0], X[:, 1], style, ms=4, label=label)
    top.set_aspect("equal")
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.legend(fontsize=7, loc="upper right")
    top.set_title(f"{site.name}: the robot's LED at h = {truth[0, 2]:g} m, seen from above",
                  fontsize=9)
    for label, fixes in fixes_of.items():
        e = np.linalg.norm(fixes.X - truth, axis=1)[np.isfinite(fixes.X[:, 0])]
        error_cdf(cdf, label, e, len(truth), dashed=label.startswith("paper"))
    cdf.set_xscale("log")
    cdf.set_xlabel("3D error (cm)")
    cdf.set_ylabel("share of frames (CDF)")
    cdf.grid(alpha=0.3)
    cdf.legend(fontsize=7)
    cdf.set_title("every pipeline on the same frames", fontsize=9)
    save_figure(fig, Path(path), dpi=110)


#: a run's figure draws this many ids by name, the most rows first (the rest grey)
PLOTTED_IDS = 8


def track_figure(path, dep, rows, title: str = "") -> None:
    """:func:`run_figure` of a tracking run's rows (:class:`~vlpcal.tracking.TrackUpdate`)."""
    t = np.array([r.t for r in rows], float)
    run_figure(path, dep, t - (t.min() if len(t) else 0.0), [r.led for r in rows],
               np.array([r.position for r in rows], float).reshape(-1, 3),
               np.array([r.sigma_m for r in rows], float), [r.status for r in rows],
               np.array([r.pose[0] if r.pose is not None else np.nan for r in rows], float),
               title, "time from the first row (s)")


def run_figure(path, dep, t, ids, X, sigma, status, yaw=None, title: str = "",
               time_label: str = "time (s)") -> None:
    """A run at a glance: on the plan, each id's path (its ``ok`` rows; rows of one camera or
    none light), a body's heading (``yaw``, NaN for none) now and then; beside it, each
    id's ``sigma`` over ``t`` (log scale over a decade), so where the fixes were loose
    shows. One row per fix or track update: ``t`` N, ``ids`` N, ``X`` N×3 m, ``sigma`` N m,
    ``status`` N."""
    plt = _pyplot()
    fig, (plan, sig) = plt.subplots(1, 2, figsize=(13, 5.2), constrained_layout=True,
                                    gridspec_kw={"width_ratios": [1.1, 1.0]})
    room = np.array(dep.room, float)
    plan.fill(*np.vstack([room, room[:1]]).T, fc="none", ec="k", lw=1.2)
    for poly in dep.keep_out:
        plan.fill(*np.array(poly, float).T, color="0.85", ec="0.5")
    for c in dep.cameras:
        plan.plot(*c.position[:2], "s", color="0.3", ms=5)
        plan.annotate(c.id, c.position[:2], fontsize=7, xytext=(3, 3),
                      textcoords="offset points", color="0.3")
    ids = np.asarray(ids, dtype=object)
    yaw = np.full(len(ids), np.nan) if yaw is None else np.asarray(yaw, float)
    named = [i for i, _ in Counter(ids.tolist()).most_common(PLOTTED_IDS)]
    placed = np.isfinite(X).all(axis=1)
    ok = (np.asarray(status, dtype=object) == "ok") & placed
    size = float(np.ptp(room, axis=0).max()) or 1.0
    for k, led in enumerate(named + ["others"]):
        mine = ids == led if led != "others" else ~np.isin(ids, named)
        if not mine.any():
            continue
        colour = f"C{k % 10}" if led != "others" else "0.6"
        good, loose = mine & ok, mine & ~ok & placed
        if good.any():
            plan.plot(X[good, 0], X[good, 1], ".", ms=2, color=colour,
                      label=f"{led} ({good.sum()} ok of {mine.sum()})")
        if loose.any():
            plan.plot(X[loose, 0], X[loose, 1], "x", ms=3, color=colour, alpha=0.4)
        posed = np.flatnonzero(good & np.isfinite(yaw))
        for i in posed[:: max(1, len(posed) // 15)]:  # a body's heading, now and then
            d = 0.05 * size * np.array([np.cos(yaw[i]), np.sin(yaw[i])])
            plan.annotate("", X[i, :2] + d, X[i, :2],
                          arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 1.2})
        s = sigma * 1000
        shown = mine & np.isfinite(s) & (s > 0)
        sig.plot(t[shown & ok], s[shown & ok], ".", ms=2, color=colour, label=led)
        sig.plot(t[shown & ~ok], s[shown & ~ok], "x", ms=3, color=colour, alpha=0.4)
    plan.set_aspect("equal")
    plan.set_xlabel("x (m)")
    plan.set_ylabel("y (m)")
    plan.set_title("paths on the plan (dots: ok; ×: not ok; arrows: a body's heading)",
                   fontsize=9)
    if plan.get_legend_handles_labels()[0]:
        plan.legend(fontsize=7, markerscale=4, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    lo, hi = sig.get_ylim()
    if hi > 10 * max(lo, 1e-12):  # over a decade: a log scale, millimetres as numbers
        from matplotlib.ticker import FuncFormatter  # (matplotlib: when drawing)

        sig.set_yscale("log")
        sig.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    sig.set_xlabel(time_label)
    sig.set_ylabel("predicted error sigma_m (mm)")
    sig.set_title("each row's sigma_m (×: not ok)", fontsize=9)
    sig.grid(alpha=0.3, which="both")
    if title:
        fig.suptitle(title, fontsize=10)
    save_figure(fig, path, dpi=100)
