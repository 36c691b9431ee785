"""Layout planning: the fewest cameras, and where, for a room and a requirement.

- :mod:`.site`: the site file (room, camera model, requirements), read strictly; the floor to
  serve and a camera's footprint on it;
- :mod:`.reference`: the reference model that judges every layout (docs/conventions.md);
- :mod:`.families`: the grid families as cameras and the mounting grid;
- :mod:`.nadir`: the reference model in closed form for level cameras, batched;
- :mod:`.lattice`: the exhaustive search over a family's lattices clipped to the room;
- :mod:`.free`: the local search beyond lattices (remove cameras, repair by moves);
- :mod:`.poses`: a ceiling camera's pose (position, yaw, tilt) as an installer sets it;
- :mod:`.optimiser`: the CasADi optimiser over poses, on a smooth form of the reference model;
- :mod:`.tilted`: fewer cameras by tilting them, the optimiser's search;
- :mod:`.plan`: the whole plan, as ``vlpcal plan`` runs it, and its deployment;
- :mod:`.check`: a given layout judged against a site;
- :mod:`.report`: the plan's and the check's terminal reports, as lines of text.
"""

from .families import (
    MOUNT_STEP,
    Candidate,
    ceiling_cameras,
    grid_cameras,
    mount_step,
    rank_key,
)
from .lattice import Mounting, SearchResult, lattice_search
from .plan import Plan, plan_site, planned_deployment
from .reference import MARGIN_PX, Evaluation, evaluate, sample_points
from .site import (
    CAMERA_KEYS,
    FAMILIES,
    FORMAT,
    REQUIREMENT_KEYS,
    SAMPLE_STEP,
    SITE_KEYS,
    VERSION,
    Requirements,
    Site,
    SiteError,
    footprint,
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
