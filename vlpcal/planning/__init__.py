"""Layout planning: the fewest cameras, and where, for a room and a requirement.

- :mod:`.site`: the site file (room, camera model, requirements), read strictly;
- :mod:`.reference`: the reference model (DESIGN.md) that judges every layout;
- :mod:`.families`: the grid families as cameras, the footprint and the mounting grid;
- :mod:`.nadir`: the reference model in closed form for level cameras, batched;
- :mod:`.lattice`: the exhaustive search over a family's lattices clipped to the room;
- :mod:`.free`: the local search beyond lattices (remove cameras, repair by moves);
- :mod:`.plan`: the whole plan, as ``vlpcal plan`` runs it, and its deployment.
"""

from .families import (
    MOUNT_STEP,
    Candidate,
    ceiling_cameras,
    footprint,
    grid_cameras,
    mount_step,
    rank_key,
)
from .lattice import Mounting, SearchResult, lattice_search
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
    "CAMERA_KEYS", "FAMILIES", "FORMAT", "MARGIN_PX", "MOUNT_STEP", "REQUIREMENT_KEYS",
    "SAMPLE_STEP", "SITE_KEYS", "VERSION", "Candidate", "Evaluation", "Mounting", "Plan",
    "Requirements", "SearchResult", "Site", "SiteError", "ceiling_cameras", "evaluate",
    "footprint", "grid_cameras", "lattice_search", "load_site", "mount_step", "plan_site",
    "planned_deployment", "rank_key", "sample_points", "site_from_dict",
]
