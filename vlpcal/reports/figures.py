"""The figures (PNG) that commands and the demo write beside their results. matplotlib is
imported inside each function (through :func:`_pyplot`): it takes most of a second to load,
and the runtime path never draws."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from ..survey import LENS_MODELS


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
    marks = hasattr(plan, "recorded") and plan.recorded is not None
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


#: a calibration report's error maps: one panel per LED height, at most this many (more
#: heights are binned)
MAP_HEIGHTS = 4


def calibration_figure(path, stats, per_point, X, cameras, lens_rows=(), rows=(),
                       title: str = "") -> None:
    """A survey calibration's report as panels that each answer one question: where each
    camera moved from its nominal place (``rows``: the report's per-camera rows, with
    ``nominal_position_m``; arrows drawn to scale, their lengths written), the held-out error
    over the floor calibrated and nominal — each on its own colour scale, one panel per LED
    height —, the error's CDF, and (``lens_rows``) each camera's lens models and the held-out
    error that chose among them."""
    plt = _pyplot()
    nom = per_point["nominal, all-camera LS"] * 100
    cal = per_point["calibrated, all-camera LS"] * 100
    band, names = _height_bands(X[:, 2])
    n_maps = len(names)
    top = 2 + bool(lens_rows)
    cols = max(n_maps, top)
    fig = plt.figure(figsize=(4.4 * cols, 3.9 * 3), constrained_layout=True)
    grid = fig.add_gridspec(3, cols)
    moved = fig.add_subplot(grid[0, 0])
    _movement_panel(moved, cameras, rows, X)
    cdf = fig.add_subplot(grid[0, 1])
    for label, err in per_point.items():
        e = np.sort(err[np.isfinite(err)] * 100)
        if len(e):
            cdf.plot(e, np.arange(1, len(e) + 1) / len(e), label=label,
                     ls="--" if label.startswith("nominal") else "-")
    cdf.set_xscale("log")
    cdf.set_xlabel("held-out 3D error (cm)")
    cdf.set_ylabel("share of held-out points")
    cdf.set_title("held-out 3D error, all points (CDF)", fontsize=10)
    cdf.grid(alpha=0.3)
    if cdf.get_legend_handles_labels()[0]:
        cdf.legend(fontsize=7, loc="lower right")
    if lens_rows:
        _lens_panel(fig.add_subplot(grid[0, 2]), lens_rows)
    for r, (err, which) in enumerate(((cal, "calibrated"), (nom, "nominal cameras")), start=1):
        ok = np.isfinite(err)
        vmax = float(np.nanpercentile(err, 95)) if ok.any() else 1.0  # its own scale
        axes = [fig.add_subplot(grid[r, k]) for k in range(n_maps)]
        for k, ax in enumerate(axes):
            here = band == k
            sc = ax.scatter(X[here & ok, 0], X[here & ok, 1], c=err[here & ok], cmap="viridis",
                            vmin=0, vmax=max(vmax, 1e-9), s=22)
            ax.scatter(X[here & ~ok, 0], X[here & ~ok, 1], marker="x", c="0.55", s=14, lw=0.8)
            for c in cameras:
                ax.plot(*c.position[:2], "s", color="0.3", ms=4)
            mean = f"mean {np.mean(err[here & ok]):.2g} cm" if (here & ok).any() else "no fix"
            ax.set_title(f"{which}, {names[k]}: {mean}", fontsize=9)
            ax.set_aspect("equal")
            ax.set_xlabel("x (m)", fontsize=8)
            ax.tick_params(labelsize=7)
        axes[0].set_ylabel("y (m)", fontsize=8)
        fig.colorbar(sc, ax=axes, label=f"held-out 3D error, {which} (cm)", shrink=0.85)
        if (~ok).any():
            axes[-1].scatter([], [], marker="x", c="0.55", label="no fix (one camera, or refused)")
            axes[-1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                            borderaxespad=0)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.canvas.draw()
    _movement_labels(moved, cameras, rows)
    save_figure(fig, path, dpi=100)


def _height_bands(z) -> tuple[np.ndarray, list[str]]:
    """The LED heights of a survey as bands to draw apart: heights part where they leave a
    gap of a twentieth of their range (a survey at 0, 0.35 and 0.7 m, each measured to a
    few millimetres: three), at most :data:`MAP_HEIGHTS` (else as many points in each).
    Returns each point's band and the bands' names."""
    z = np.asarray(z, float)
    order = np.sort(z)
    span = float(order[-1] - order[0]) if len(z) else 0.0
    cuts = order[:-1][np.diff(order) > span / 20] if span > 0 else np.zeros(0)
    if len(cuts) >= MAP_HEIGHTS or (span > 0 and not len(cuts)):  # too many heights, or
        # heights spread without a gap: bands of as many points
        cuts = np.quantile(z, np.linspace(0, 1, MAP_HEIGHTS + 1)[1:-1])
    band = np.searchsorted(cuts, z, side="left")
    names = []
    for k in range(len(cuts) + 1):
        h = z[band == k]
        lo, hi = (float(h.min()), float(h.max())) if len(h) else (0.0, 0.0)
        mid, lo, hi = (round(float(v), 2) + 0.0 for v in (np.median(h) if len(h) else 0.0,
                                                            lo, hi))  # no "-0.00"
        names.append(f"LED at {mid:.2f} m" if hi - lo <= max(span / 20, 1e-9)
                     else f"LED {lo:.2f}–{hi:.2f} m")
    return band, names


def _movement_panel(ax, cameras, rows, X) -> None:
    """Each camera from its nominal place (hollow) to where the survey put it (filled), the
    arrow drawn longer by a factor written in the title so that millimetres show on a room."""
    nominal = {r["camera"]: np.asarray(r["nominal_position_m"], float) for r in rows
               if r.get("nominal_position_m") is not None}
    size = float(np.ptp(np.vstack([X[:, :2]] + [c.position[:2] for c in cameras]),
                        axis=0).max()) or 1.0
    moves = [np.linalg.norm(c.position[:2] - nominal[c.id][:2]) for c in cameras
             if c.id in nominal]
    largest = max(moves, default=0.0)
    scale = 1.0
    if largest > 0:  # the longest arrow a sixth of the room or less, a round factor (1-2-5)
        want = size / 6 / largest
        decade = 10 ** np.floor(np.log10(want))
        scale = float(max(f * decade for f in (1, 2, 5) if f * decade <= want))
    ax.scatter(X[:, 0], X[:, 1], s=4, c="0.85")
    for c in cameras:
        if c.id in nominal:
            n = nominal[c.id]
            ax.plot(*n[:2], "s", mfc="none", mec="C0", ms=7)
            end = n[:2] + scale * (c.position[:2] - n[:2])
            ax.annotate("", end, n[:2], arrowprops={"arrowstyle": "-|>", "color": "C3",
                                                    "lw": 1.6}, zorder=3)
        else:
            ax.plot(*c.position[:2], "s", color="C3", ms=5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title(f"camera moves from nominal (□), arrows ×{scale:g}", fontsize=10)
    ax.margins(0.12)


def _movement_labels(ax, cameras, rows) -> None:
    """Each camera's id, how far it moved (mm, in 3D) and turned (°), placed clear of the
    others' (the figure's layout final)."""
    by_id = {r["camera"]: r for r in rows}
    labels = []
    for c in cameras:
        r = by_id.get(c.id, {})
        text = c.id
        if r.get("moved_m") is not None:
            text += f" {1000 * r['moved_m']:.0f} mm"
        if r.get("turned_deg") is not None:
            text += f", {r['turned_deg']:.1f}°"
        labels.append((c.position[:2], text, {"fontsize": 7}))
    _place_labels(ax, labels)


def _lens_panel(ax, rows) -> None:
    """Per camera, the held-out error that chose its lens model, for each model fitted: the 3D
    error of held-out survey points (cm) where the choice was made by it, else the camera's
    held-out reprojection error (px); the chosen model filled, the others hollow."""
    in_3d = any(c.get("held_out_3d_m") is not None
                for r in rows for c in r.get("lens_candidates", {}).values())
    key, scale = ("held_out_3d_m", 100.0) if in_3d else ("held_out_px", 1.0)
    width = 0.8 / len(LENS_MODELS)
    for j, model in enumerate(LENS_MODELS):
        xs, ys, chosen = [], [], []
        for i, r in enumerate(rows):
            v = r.get("lens_candidates", {}).get(model, {}).get(key)
            if v is not None:
                xs.append(i - 0.4 + (j + 0.5) * width)
                ys.append(v * scale)
                chosen.append(model == r.get("lens_model"))
        colour = f"C{j}"
        ax.bar(xs, ys, width, color=[colour if c else "none" for c in chosen],
               edgecolor=colour, label=model)
    ax.set_xticks(range(len(rows)), [r["camera"] for r in rows], fontsize=7)
    ax.set_ylabel("held-out 3D error (cm; the other cameras as chosen)" if in_3d
                  else "held-out reprojection error (px)", fontsize=8)
    heights = [b.get_height() for b in ax.patches if np.isfinite(b.get_height())]
    if heights and min(heights) > 0:  # the models differ by little: the axis from near the
        lo, hi = min(heights), max(heights)  # least, said in the title
        ax.set_ylim(max(0.0, lo - 0.15 * (hi - lo + 1e-12)), hi + 0.1 * (hi - lo + 1e-12))
    note = f" (axis from {ax.get_ylim()[0]:.3g})" if ax.get_ylim()[0] > 0 else ""
    ax.set_title(f"lens model per camera (filled: chosen){note}", fontsize=9)
    ax.legend(fontsize=6, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.08),
              frameon=False)
    ax.grid(alpha=0.3, axis="y")


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


def free_calibration_figure(path, result) -> None:
    """A free survey seen from above — where the LED went (coloured by how many cameras saw
    it: where the motion covered the room poorly shows), the references with their
    left-out errors, the cameras — and each reference's left-out error beside the datum
    floor the references allow. ``result``: a ``survey.FreeSurveyResult``."""
    plt = _pyplot()
    cal, dep = result.calibration, result.deployment
    fig, (top, bars) = plt.subplots(1, 2, figsize=(13, 5), constrained_layout=True,
                                    gridspec_kw={"width_ratios": [1.6, 1]})
    room = np.array(list(dep.room) + [dep.room[0]])
    top.plot(room[:, 0], room[:, 1], "k-", lw=1)
    F = cal.free_xyz
    ok = np.isfinite(F).all(axis=1)
    if ok.any():
        views = np.array([c.project(F[ok])[2] for c in dep.cameras])
        most = max(2, len(dep.cameras))
        sc = top.scatter(F[ok, 0], F[ok, 1], c=views.sum(axis=0), s=4,
                         cmap=plt.get_cmap("viridis", most), vmin=0.5, vmax=most + 0.5)
        fig.colorbar(sc, ax=top, label="cameras that see the fitted LED position",
                     ticks=range(1, most + 1))
    recorded = np.asarray(result.points, float)
    marks_only = cal.marks_only
    what = "marks" if marks_only else "reference points"
    # where the fit put them: a mark's empty cells have no record to draw
    placed = np.where(np.isfinite(recorded), recorded, cal.references)
    top.plot(placed[:, 0], placed[:, 1], "r^", ms=7, label=what)
    for pid, p, e in zip(result.reference_ids, placed, cal.leave_one_out):
        top.annotate(pid + (f" {e * 1000:.1f} mm" if np.isfinite(e) else ""), p[:2],
                     fontsize=7, xytext=(4, 4), textcoords="offset points", color="r")
    for c in dep.cameras:
        top.plot(*c.position[:2], "ks", ms=6)
        top.annotate(c.id, c.position[:2], fontsize=8, xytext=(4, -10), textcoords="offset points")
    top.set_aspect("equal")
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.legend(fontsize=7, loc="upper right")
    top.set_title(f"{dep.name}: {cal.used_sets} free LED positions fitted of "
                  f"{result.free_sets} sets", fontsize=9)
    e = cal.leave_one_out * 1000
    shown = np.isfinite(e)  # a reference the rest cannot do without has no bar
    bars.bar(np.flatnonzero(shown), e[shown], color="#2a7ab0")
    bars.axhline(cal.datum_floor * 1000, color="r", ls="--",
                 label=f"datum floor {cal.datum_floor * 1000:.1f} mm")
    own = cal.point_sigma * 1000 * (1.0 if marks_only else np.sqrt(3))
    bars.axhline(own, color="0.5", ls=":",
                 label=(f"the floor's unevenness under them {own:.1f} mm" if marks_only else
                        f"the tape's own 3D noise {own:.1f} mm"))
    if np.isfinite(cal.predicted_error):
        bars.axhline(cal.predicted_error * 1000, color="#d07000", ls="-.",
                     label=f"fixes predicted {cal.predicted_error * 1000:.1f} mm off"
                     + (" (weakly fixed)" if cal.weakly_fixed else ""))
    bars.set_xticks(range(len(e)), result.reference_ids, rotation=90, fontsize=7)
    bars.set_ylabel("left-out error (mm)")
    bars.legend(fontsize=7)
    bars.set_title(f"each of the {what} fitted without it, against its record", fontsize=9)
    save_figure(fig, path, dpi=110)


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
        e = np.sort(np.linalg.norm(fixes.X - truth, axis=1)[np.isfinite(fixes.X[:, 0])] * 100)
        if len(e):
            cdf.plot(e, np.arange(1, len(e) + 1) / len(truth), label=label,
                     ls="--" if label.startswith("paper") else "-")
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
