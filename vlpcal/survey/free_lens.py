"""A free survey's lens models: one for every camera, chosen by how consistently the free LED
is seen held out of the fit; a robot's LED at one height keeps the deployment's lens unless
the references fix the rest; each camera's decision in words' terms."""

from __future__ import annotations

import numpy as np

from ..triangulation import reprojection_errors, triangulate
from .calibration import _lens_choice, refine_jointly
from .camera_fit import fit_camera
from .lens import LENS_MODELS


def robot_lens(lens, free_height, seen_r, X0, ids_c) -> tuple[str, str]:
    """A robot's LED shows each camera one plane: the references must fix the rest of its
    lens, which needs three or more of them in its view at two heights or more. Returns the
    lens asked for (``"pose"`` where some camera lacks them) and why it was kept ("")."""
    if not (lens == "auto" and free_height is not None):
        return lens, ""
    weak = [ids_c[k] for k in range(len(ids_c))
            if seen_r[k].sum() < 3 or np.ptp(X0[seen_r[k], 2]) <= 0]
    if not weak:
        return lens, ""
    return "pose", (f"camera{'s' if len(weak) > 1 else ''} {', '.join(weak)} "
                    f"{'see' if len(weak) > 1 else 'sees'} fewer than three reference points "
                    "at two heights, and a robot's LED at one height cannot fix a lens alone")


def lens_models(fit, u, lens, cams, adj, keep, s_x, s_px):
    """Every camera's lens model: ``auto`` one for all, chosen by the free LED's held-out
    consistency (:func:`joint_lens_choice`), with each camera's choice; else the model
    asked for. Returns (models, choices: [] where asked)."""
    C = len(cams)
    if lens != "auto":
        if lens not in LENS_MODELS:
            raise ValueError(f"lens: expected auto or one of {', '.join(LENS_MODELS)}")
        return [lens] * C, []
    chosen, held = joint_lens_choice(cams, adj, fit.prior(u, s_x), u.uv_all, keep, u.free,
                                      s_px, lengths=fit.lengths(u, keep), aspect=fit.aspect)
    choices = []
    for k, cam in enumerate(cams):
        idx = np.flatnonzero(keep[k])
        one = fit_camera(fit.nominal[k], adj[idx], u.uv_all[k, idx], [""] * len(idx), chosen,
                         start=cam)
        cand = {m: {"held_out_px": v, "supported": True, "reason": ""}
                for m, v in held.items()}
        choices.append(_lens_choice(one, cam.id, False, cand, adj[idx]))
    return [chosen] * C, choices


def forced_choices(fit, u, models, cams, adj, keep, kept: str) -> list:
    """Each camera's lens decision where the model was set, not chosen (``kept``: why the
    survey set it, when it did)."""
    choices = []
    for k, cam in enumerate(cams):
        idx = np.flatnonzero(keep[k])
        one = fit_camera(fit.nominal[k], adj[idx], u.uv_all[k, idx], [""] * len(idx),
                         models[k], start=cam)
        choice = _lens_choice(one, cam.id, True, {}, adj[idx])
        if kept:
            choice.reason = f"kept as in the deployment, as {kept}"
        choices.append(choice)
    return choices


def joint_lens_choice(cams, P, sig, uv_all, keep, free, s_px, sets: int = 1200,
                       folds: int = 2, lengths=None, aspect=None):
    """One lens model for every camera, chosen by held-out consistency of the free LED: per
    model, the joint fit on the references and all but a fold of (a sample of) the free sets,
    then the held-out sets triangulated with the fitted cameras and their reprojection error —
    with two views, how far the spots are from seeing one point. The simplest model within one
    standard error of the best (paired over the sets). ``lengths``: a wand's (as
    :func:`~.calibration.refine_jointly` takes them), kept where both LEDs are in a fold's
    fit; ``aspect``: the focal lengths' ratios, as it takes them too. Returns (model,
    {model: held-out px})."""
    C = len(cams)
    cols = np.flatnonzero(free & (keep.sum(axis=0) >= 2))
    sub = np.random.default_rng(0).permutation(cols)[:sets]
    fold = np.arange(len(sub)) % folds
    fixed = np.flatnonzero(~free)
    loss, px = {}, {}
    for m in LENS_MODELS:
        e = np.full(len(sub), np.nan)
        for f in range(folds):
            train = np.r_[fixed, sub[fold != f]]
            test = sub[fold == f]
            kk = keep[:, train]
            obs = [(np.flatnonzero(kk[k]), uv_all[k, train][kk[k]]) for k in range(C)]
            held = None
            if lengths is not None:
                at = np.full(len(P), -1)
                at[train] = np.arange(len(train))
                a, b = at[lengths[0]], at[lengths[1]]
                both = (a >= 0) & (b >= 0)
                held = (a[both], b[both], *lengths[2:])
            try:
                fitted, _ = refine_jointly(cams, P[train], obs, point_sigma=sig[train],
                                           pixel_sigma=s_px, models=[m] * C, iterations=25,
                                           lengths=held, aspect=aspect)
            except (ValueError, np.linalg.LinAlgError):
                break
            uvt = np.where(keep[:, test, None], uv_all[:, test], np.nan)
            X = triangulate(fitted, uvt).X
            r = reprojection_errors(fitted, uvt, X)
            sq = np.where(np.isfinite(uvt[..., 0]) & np.isfinite(r), r, 0.0) ** 2
            n = (np.isfinite(uvt[..., 0]) & np.isfinite(r)).sum(axis=0)
            e[fold == f] = np.where(n > 0, np.sqrt(sq.sum(axis=0) / np.maximum(n, 1)), np.nan)
        if not np.isfinite(e).any():
            break
        loss[m], px[m] = e ** 2, float(np.sqrt(np.nanmean(e ** 2)))
    ok = np.logical_and.reduce([np.isfinite(v) for v in loss.values()])
    if len(loss) < 2 or ok.sum() < 2:
        return "pose", px
    best = min(loss, key=lambda m: loss[m][ok].mean())
    for m in loss:
        d = loss[m][ok] - loss[best][ok]
        if d.mean() <= d.std(ddof=1) / np.sqrt(len(d)):
            return m, px
    return best, px
