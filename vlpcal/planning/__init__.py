"""Layout planning: the fewest cameras, and where, for a room and a requirement.

- :mod:`.site`: the site file (room, camera model, requirements), read strictly;
- :mod:`.reference`: the reference model (DESIGN.md) that judges every layout;
- :mod:`.families`: the grid families, their candidates and the closed-form bounds;
- :mod:`.exhaustive`: the exhaustive search, the baseline;
- :mod:`.optimiser`: the CasADi/IPOPT optimiser on smooth surrogates;
- :mod:`.plan`: the whole plan, as ``vlpcal plan`` runs it, and its deployment.
"""

from .exhaustive import exhaustive_search
from .families import (
    Candidate,
    arrangements,
    footprint,
    grid_cameras,
    lower_bound,
    mountable,
    promising,
    rank_key,
    shapes,
)
from .optimiser import PENALTY, optimise_layout
from .plan import Plan, plan_site, planned_deployment
from .reference import MARGIN_PX, SAMPLE_STEP, Evaluation, evaluate, sample_points
from .site import (
    CAMERA_KEYS,
    FAMILIES,
    FORMAT,
    REQUIREMENT_KEYS,
    SITE_KEYS,
    VERSION,
    Requirements,
    Site,
    SiteError,
    load_site,
    site_from_dict,
)

__all__ = [
    "CAMERA_KEYS", "FAMILIES", "FORMAT", "MARGIN_PX", "PENALTY", "REQUIREMENT_KEYS",
    "SAMPLE_STEP", "SITE_KEYS", "VERSION", "Candidate", "Evaluation", "Plan", "Requirements",
    "Site", "SiteError", "arrangements", "evaluate", "exhaustive_search", "footprint",
    "grid_cameras", "load_site", "lower_bound", "mountable", "optimise_layout", "plan_site",
    "planned_deployment", "promising", "rank_key", "sample_points", "shapes", "site_from_dict",
]
