"""A survey calibration's figure: a tape survey's held-out error maps, how far each camera
moved and its lens models' held-out errors; a free survey's map of where the LED went, the
references left out in turn and the datum floor."""

from __future__ import annotations

import numpy as np

from ..survey import LENS_MODELS
from .figures import _place_labels, _pyplot, error_cdf, save_figure

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
        e = err[np.isfinite(err)]
        error_cdf(cdf, label, e, len(e), dashed=label.startswith("nominal"))
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
