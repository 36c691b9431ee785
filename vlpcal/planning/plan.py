"""The whole plan, as ``vlpcal plan`` runs it: camera counts from the lower bound up, every
family and arrangement optimised, the first count with a passing layout wins."""

from __future__ import annotations

from dataclasses import dataclass

from ..deployment import Deployment, provenance
from .families import Candidate, arrangements, lower_bound, rank_key
from .optimiser import optimise_layout
from .site import Site


@dataclass
class Plan:
    """The result of planning: ranked candidates at the fewest cameras that meet the site's
    requirements (empty when none up to ``max_cameras`` does), and the best seen otherwise."""

    candidates: list  # Candidate, best p95 first
    tried: int  # arrangements optimised
    seconds: float
    closest: Candidate | None = None  # when nothing meets: the best coverage seen


def plan_site(site: Site, max_cameras: int = 60, starts: int = 3, progress=None) -> Plan:
    """The fewest cameras that meet the requirements: for each count from a lower bound up, every
    family and arrangement (nx × ny) and both yaws, spacing and offset by
    :func:`optimise_layout`, each result judged by :func:`evaluate`; the first count with a
    passing layout ends the search and its candidates are ranked by predicted p95."""
    import time


    t0 = time.perf_counter()
    tried, closest = 0, None
    for n in range(lower_bound(site), max_cameras + 1):
        found = []
        for family, nx, ny, yaw in arrangements(site, n):
            tried += 1
            c = optimise_layout(site, family, nx, ny, yaw, starts)
            if c is None:
                continue
            if c.evaluation.meets:
                found.append(c)
            elif closest is None or rank_key(c) < rank_key(closest):
                closest = c
        if progress and next(arrangements(site, n), None):
            progress(n)
        if found:
            return Plan(sorted(found, key=rank_key), tried, time.perf_counter() - t0)
    return Plan([], tried, time.perf_counter() - t0, closest)


def planned_deployment(site: Site, cand: Candidate, rank: int = 1, source: str = "") -> Deployment:
    """The deployment file of a planned layout, with its predicted figures in the provenance
    (so that the survey can later report planned against achieved)."""
    ev, r = cand.evaluation, site.requirements
    prov = provenance(
        "vlpcal plan", **{"from": {"site": str(source)}},
        plan={"family": cand.family, "grid": [cand.nx, cand.ny],
              "spacing_m": [float(v) for v in cand.spacing],
              "origin_m": [float(v) for v in cand.origin],
              "yaw_rad": float(cand.yaw), "rank": rank},
        predicted={"coverage": ev.coverage, "mean_error_m": ev.mean, "p95_error_m": ev.p95,
                   "model": "reference model (docs/formats.md)", "pixel_noise_px": r.pixel_noise})
    return Deployment(site.name, site.ceiling_height, site.room, cand.cameras, site.keep_out,
                      {"uncertainty": {"pixel_noise": r.pixel_noise}, "provenance": prov})
