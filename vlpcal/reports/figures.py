"""The figures (PNG) that commands and the demo write beside their results — here a plan's
maps and a survey plan's; a calibration's in :mod:`.calibration_figures`, a run's in
:mod:`.run_figures` — and what they share: matplotlib, imported inside each function (through
:func:`_pyplot`) because it is slow to load and the runtime path never draws, and labels placed
where they overlap no other."""

from __future__ import annotations

import numpy as np

from ..survey.free_plan import FrameMarks


def _pyplot():
    """matplotlib's pyplot on the file-only backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, dpi: int = 110) -> None:
    """Write a matplotlib figure as PNG to ``path`` (a staging path of the caller's
    :class:`~vlpcal.writing.OutputSet`: a figure is always part of a set) and close it."""
    plt = _pyplot()
    try:
        fig.savefig(path, dpi=dpi, format="png")
    finally:
        plt.close(fig)


#: a survey map's panel numbers its points up to this many
LABELLED_POINTS = 150


#: offsets (points) a map's label tries, nearest first, until it overlaps no other label
LABEL_OFFSETS = [(4, 4), (4, -4), (-4, 4), (-4, -4), (6, 0), (-6, 0), (0, 7), (0, -7),
                 (10, 10), (10, -10), (-10, 10), (-10, -10), (16, 0), (-16, 0), (0, 16), (0, -16),
                 (18, 18), (18, -18), (-18, 18), (-18, -18)]


def error_cdf(ax, label: str, errors_m, total: int, dashed: bool = False) -> None:
    """One pipeline's 3D errors (m) as a CDF in cm: the share of ``total`` points within each
    error (points with no fix never reach 1); nothing where there is no error to draw."""
    e = np.sort(np.asarray(errors_m, float) * 100)
    if len(e):
        ax.plot(e, np.arange(1, len(e) + 1) / total, label=label, ls="--" if dashed else "-")


def _place_labels(ax, labels, avoid=()) -> list:
    """Put each label ``(xy, text, style)`` beside its point at the first of
    :data:`LABEL_OFFSETS` where it overlaps no label placed before it nor a box of ``avoid``
    (display coordinates), else where it overlaps least; returns the placed boxes. Call it once
    the figure's layout is final: text keeps its size in points while the axes scale."""
    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    taken = np.zeros((len(avoid) + len(labels), 4))  # x0, y0, x1, y1 of each box so far
    if len(avoid):
        taken[: len(avoid)] = [(b.x0, b.y0, b.x1, b.y1) for b in avoid]
    n = len(avoid)
    placed = []

    def overlap(bb):  # with other labels and points, and what sticks out of the panel
        inside = max(0.0, min(bb.x1, frame.x1) - max(bb.x0, frame.x0)) \
            * max(0.0, min(bb.y1, frame.y1) - max(bb.y0, frame.y0))
        o = taken[:n]
        w = (np.minimum(bb.x1, o[:, 2]) - np.maximum(bb.x0, o[:, 0])).clip(0)
        h = (np.minimum(bb.y1, o[:, 3]) - np.maximum(bb.y0, o[:, 1])).clip(0)
        return bb.width * bb.height - inside + float(w @ h)

    for xy, text, style in labels:
        best = None
        for dx, dy in LABEL_OFFSETS:
            t = ax.annotate(text, xy, xytext=(dx, dy), textcoords="offset points",
                            ha="left" if dx > 0 else "right" if dx < 0 else "center",
                            va="bottom" if dy > 0 else "top" if dy < 0 else "center", **style)
            bb = t.get_window_extent(renderer).expanded(1.05, 1.1)
            cost = overlap(bb)
            if best is None or cost < best[0]:
                if best is not None:
                    best[1].remove()
                best = (cost, t, bb)
            else:
                t.remove()
            if cost == 0:
                break
        b = best[2]
        taken[n] = (b.x0, b.y0, b.x1, b.y1)
        n += 1
        placed.append(b)
    return placed


def survey_plan_figure(path, dep, plan, route=None) -> list:
    """One panel per height: room, keep-out areas, cameras, points with their ids (a wand
    survey's frame marks: O, X, F1…); with a free survey's ``route``
    (:class:`vlpcal.survey.FreeRoute`) its stops, numbered, on every panel — those swept only
    low (a thin overlap) in another colour — and cameras the route cannot link ringed, with
    where another camera would link them. Labels are placed so that none overlaps another
    (:func:`_place_labels`); returns their boxes (display coordinates), for a check."""
    from matplotlib.transforms import Bbox  # (matplotlib: when drawing)

    plt = _pyplot()
    heights = sorted(set(plan.xyz[:, 2].round(6)))
    room = np.array(dep.room + dep.room[:1])
    span = np.ptp(room, axis=0)
    aspect = float(np.clip(span[1] / max(span[0], 1e-12), 0.3, 2.0))
    fig, axes = plt.subplots(1, len(heights), figsize=(max(5.5 * len(heights), 8.0),
                                                      5.5 * aspect + 1.8),
                             squeeze=False, constrained_layout=True)
    marks = isinstance(plan, FrameMarks) and plan.recorded is not None
    unlinked, remedies = [], []
    if route is not None and route.linkage is not None and len(route.groups) > 1:
        unlinked = [c for g in route.groups[1:] for c in g]
        remedies = [r for r in route.linkage.remedies if r.camera_at is not None]
    low = (np.zeros(0, bool) if route is None
           else np.asarray(route.tops) < route.high - 1e-9)
    pending = []  # per panel: (ax, labels, anchor points to keep clear)
    for ax, h in zip(axes[0], heights):
        labels, anchors = [], []
        ax.plot(room[:, 0], room[:, 1], "k-", lw=1)
        for poly in dep.keep_out:
            poly = poly["polygon"] if isinstance(poly, dict) else poly
            ax.fill(*np.array(poly).T, color="0.85", hatch="//", ec="0.5")
        for c in dep.cameras:
            ax.plot(*c.position[:2], "rs", ms=7)
            anchors.append((*c.position[:2], 9 if c.id in unlinked else 4))
            if c.id in unlinked:
                first = ax is axes[0][0] and c.id == unlinked[0]
                ax.plot(*c.position[:2], "o", ms=17, mfc="none", mec="#c00000", mew=1.8,
                        label="camera the free LED cannot link" if first else None)
            labels.append((c.position[:2], c.id + (" not linked" if c.id in unlinked else ""),
                           {"color": "#c00000" if c.id in unlinked else "r", "fontsize": 8}))
        for r in remedies:
            first = ax is axes[0][0] and r is remedies[0]
            ax.plot(*r.camera_at, "s", ms=11, mfc="none", mec="#c00000", ls="none", mew=1.2,
                    label="another camera here would link them" if first else None)
            anchors.append((*r.camera_at, 6))
            labels.append((r.camera_at, "add a camera?", {"color": "#c00000", "fontsize": 7}))
        sel = np.flatnonzero(np.isclose(plan.xyz[:, 2], h))
        if not marks:
            ax.plot(plan.xyz[sel, 0], plan.xyz[sel, 1], "-", color="0.8", lw=0.6)  # walking order
        ax.plot(plan.xyz[sel, 0], plan.xyz[sel, 1], "D" if marks else "o", color="#2a7ab0",
                ms=6 if marks else 4)
        anchors.extend((x, y, 4) for x, y in plan.xyz[sel, :2])
        few = route is not None  # a few references or marks: their ids in full
        if len(sel) <= LABELLED_POINTS:  # beyond, numbers would smear: the CSV has them
            for i in sel:
                text = plan.ids[i] if few else plan.ids[i][1:].lstrip("0")
                labels.append((plan.xyz[i, :2], text,
                               {"fontsize": 9 if marks else 7 if few else 5, "color": "#2a7ab0",
                                "weight": "bold" if marks else "normal"}))
        if route is not None:
            ax.plot(route.stops[:, 0], route.stops[:, 1], "-", color="#d08020", lw=1.2,
                    alpha=0.8, label=f"{'wand' if marks else 'free LED'}: sweep "
                                     f"{route.low:g}–{route.high:g} m at each stop"
                                     if ax is axes[0][0] else None)
            ax.plot(*route.stops[~low].T, "o", color="#d08020", ms=3)
            if low.any():
                tops = sorted(set(np.round(np.asarray(route.tops)[low], 2)))
                said = f"to {tops[0]:g} m" if len(tops) == 1 else "as low as the words say"
                ax.plot(*route.stops[low].T, "v", color="#7a30a0", ms=6,
                        label=f"sweep only {said} here (a thin overlap)"
                        if ax is axes[0][0] else None)
            anchors.extend((x, y, 4) for x, y in route.stops)
            for n, (xy, lo) in enumerate(zip(route.stops, low), start=1):
                labels.append((xy, str(n), {"fontsize": 7, "weight": "bold",
                                            "color": "#7a30a0" if lo else "#b06000"}))
        if marks:
            title = f"frame marks on the floor: {', '.join(plan.ids)}"
        else:
            ids = (f"{plan.ids[sel[0]]}…" if len(sel) <= LABELLED_POINTS else
                   f"{plan.ids[sel[0]]}–{plan.ids[sel[-1]]}, in walking order: ids in the CSV")
            title = f"LED at h = {h:g} m: {len(sel)} point{'s' if len(sel) != 1 else ''} ({ids})"
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        pending.append((ax, labels, anchors))
    axes[0][0].set_ylabel("y (m)")
    handles = axes[0][0].get_legend_handles_labels()
    if handles[0]:
        fig.legend(*handles, loc="outside lower center", fontsize=8, frameon=False,
                   ncol=min(2, len(handles[0])))
    what = ("put the frame marks, then wave the wand along the route" if marks else
            "measure each reference point, then carry the LED along the route"
            if route is not None else "place the LED at each point, measure, record")
    fig.suptitle(f"Survey plan for {dep.name}: {what}", fontsize=10)
    fig.canvas.draw()  # the layout is final: then labels, placed in display units
    fig.set_layout_engine("none")
    boxes = []
    px = fig.dpi / 72  # pixels a point
    for ax, labels, anchors in pending:
        a = np.reshape(np.asarray(anchors, float), (-1, 3))
        clear = [Bbox.from_bounds(x - r * px, y - r * px, 2 * r * px, 2 * r * px)
                 for (x, y), r in zip(ax.transData.transform(a[:, :2]), a[:, 2])]
        boxes.append(_place_labels(ax, labels, clear))
    save_figure(fig, path, dpi=130)
    return [b for panel in boxes for b in panel]


def plan_maps(path, site, cand) -> None:
    """Per LED height: how many cameras see each point (discrete colours, one scale for every
    height) and the predicted RMS error (one scale that includes the requirement, its cut
    shown), the points that fail the requirement outlined in red, the cameras with their ids
    and the direction of each image's long side; axes in metres."""
    from matplotlib import patheffects  # (matplotlib: when drawing)
    from matplotlib.colors import BoundaryNorm

    plt = _pyplot()
    ev = cand.evaluation
    r = site.requirements
    levels = sorted(set(ev.points[:, 2].round(6)))
    fig, axes = plt.subplots(2, len(levels), figsize=(4.6 * len(levels), 7.6), squeeze=False,
                             constrained_layout=True)
    room = np.array(list(site.room) + [site.room[0]])
    finite = np.isfinite(ev.error)
    need = r.max_error_p95 * 100
    top = max(float(np.percentile(ev.error[finite], 99) * 100) if finite.any() else need,
              1.25 * need)
    cut = finite.any() and float(np.nanmax(ev.error) * 100) > top
    # counts past k + 6 share the last colour ("or more"): thousands of cameras make no
    # thousand-tick colour bar
    most = int(min(max(ev.views.max(initial=0), r.min_cameras), r.min_cameras + 6))
    counts = plt.get_cmap("viridis", most + 1)
    norm = BoundaryNorm(np.arange(-0.5, most + 1.5), most + 1)
    too_few = ev.views < r.min_cameras
    fails = too_few | ~(ev.error <= r.max_error_p95)
    size = np.ptp(room, axis=0).max()
    halo = [patheffects.withStroke(linewidth=2, foreground="white")]
    for col, h in enumerate(levels):
        sel = np.isclose(ev.points[:, 2], h)
        x, y = ev.points[sel, 0], ev.points[sel, 1]
        xs, ys = np.unique(x.round(9)), np.unique(y.round(9))
        ix, iy = np.searchsorted(xs, x.round(9)), np.searchsorted(ys, y.round(9))
        step = float(np.min(np.diff(xs))) if len(xs) > 1 else 0.1
        ex = np.r_[xs - step / 2, xs[-1] + step / 2]
        ey = np.r_[ys - step / 2, ys[-1] + step / 2]
        for row in (0, 1):
            ax = axes[row][col]
            grid = np.full((len(ys), len(xs)), np.nan)
            if row == 0:
                grid[iy, ix] = np.minimum(ev.views[sel], most)
                sc = ax.pcolormesh(ex, ey, grid, cmap=counts, norm=norm)
                title = f"h = {h:g} m: cameras that see the point (need {r.min_cameras})"
                fig.colorbar(sc, ax=ax, shrink=0.7, ticks=range(most + 1))
                bad = too_few[sel]
            else:
                grid[iy, ix] = ev.error[sel] * 100
                sc = ax.pcolormesh(ex, ey, grid, cmap="magma_r", vmin=0, vmax=top)
                title = (f"h = {h:g} m: predicted RMS 3D error, cm (need p95 ≤ {need:g})")
                bar = fig.colorbar(sc, ax=ax, shrink=0.7, extend="max" if cut else "neither")
                bar.ax.axhline(need, color="red", lw=1)
                bar.set_label(f"red line: the {need:g} cm requirement"
                              + (f"; cut at {top:.2g} cm" if cut else ""), fontsize=7)
                bad = fails[sel]
            if bad.any():
                ax.scatter(x[bad], y[bad], s=7, marker="s", facecolors="none",
                           edgecolors="red", linewidths=0.4)
            ax.plot(room[:, 0], room[:, 1], "k-", lw=1)
            for poly in site.keep_out:
                ax.fill(*np.array(poly).T, color="0.85", ec="0.5")
            for ob in site.obstacles:  # an obstacle: darker, its height written on it
                ax.fill(*np.array(ob.polygon).T, facecolor="0.7", edgecolor="0.1",
                        hatch="////", lw=0.8)
                ax.annotate(f"{ob.height:g} m", np.mean(ob.polygon, axis=0), fontsize=6,
                            ha="center", va="center", path_effects=halo)
            for c in cand.cameras:
                px, py = c.position[:2]
                if row == 0:  # where the camera's image falls at this height
                    quad = c.footprint(h)
                    if np.isfinite(quad).all():
                        ax.plot(quad[:, 0], quad[:, 1], "-", color="0.15", lw=0.5,
                                alpha=0.6)
                d = np.asarray(c.R[0][:2], float)  # the image's x axis (its long side)
                d = d / (np.hypot(*d) or 1.0) * 0.04 * size
                ax.plot([px - d[0], px + d[0]], [py - d[1], py + d[1]], "k-", lw=1.2)
                ax.plot(px, py, "c^", ms=6, mec="k")
                tilt = np.degrees(c.tilt)
                ax.annotate(c.id + (f" {tilt:.0f}°" if tilt >= 0.5 else ""), (px, py),
                            fontsize=7, xytext=(3, 3), textcoords="offset points",
                            path_effects=halo)
                if tilt >= 0.5:  # an arrow along the optical axis' lean
                    a = c.axis[:2] / np.hypot(*c.axis[:2]) * 0.09 * size
                    ax.annotate("", (px + a[0], py + a[1]), (px, py),
                                arrowprops={"arrowstyle": "-|>", "lw": 1.2,
                                            "color": "tab:blue"})
            ax.set_aspect("equal")
            pad = 0.04 * size  # the room, not the footprints, sets the frame
            ax.set_xlim(room[:, 0].min() - pad, room[:, 0].max() + pad)
            ax.set_ylim(room[:, 1].min() - pad, room[:, 1].max() + pad)
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
            ax.set_title(title, fontsize=8)
    p95 = f"{ev.p95 * 100:.2f} cm" if np.isfinite(ev.p95) else "–"
    fig.suptitle(f"{site.name}: {cand.count} cameras, {cand.family} — coverage "
                 f"{ev.coverage:.1%} (need {r.coverage:.0%}), predicted p95 {p95} over the "
                 "covered points\nred outline: a point that fails the requirement (too few "
                 "cameras, or too large an error); black bar: each image's long side\n"
                 "top row: each image's footprint at that height"
                 + ("; blue arrow and °: which way and how far a camera tilts" if any(
                     c.axis[2] > -np.cos(np.radians(0.5)) for c in cand.cameras) else "")
                 + ("; hatched: an obstacle that hides what is behind it (its height)"
                    if site.obstacles else ""), fontsize=10)
    save_figure(fig, path, dpi=110)
