"""Write ``paper-2024/spots.csv``: the spots the paper-2024 survey's cameras saw (detected from
its frames with the deployment's detector), as ``frame_id,camera_id,u,v`` — the input that
``vlpcal locate --observations`` reads when cameras report spots instead of frames.

    python surveys/make_spots.py
"""

from pathlib import Path

import numpy as np

from vlpcal.datasets import read_survey_bundle
from vlpcal.deployment import load
from vlpcal.survey.spots import survey_spots
from vlpcal.writing import OutputSet

HERE = Path(__file__).resolve().parent / "paper-2024"

dep = load(HERE / "truth.yaml")
bundle = read_survey_bundle(HERE / "survey")
uv, _ = survey_spots(dep, bundle)
rows = ["frame_id,camera_id,u,v"]
for i, pid in enumerate(bundle.point_ids[:24]):
    for k, cam in enumerate(dep.cameras):
        if np.isfinite(uv[k, i]).all():
            rows.append(f"{pid},{cam.id},{uv[k, i, 0]:.3f},{uv[k, i, 1]:.3f}")
with OutputSet(HERE / "spots.csv") as (tmp,):
    tmp.write_text("\n".join(rows) + "\n", encoding="utf-8")
print(f"{len(rows) - 1} spots of {min(24, len(bundle.point_ids))} points → {HERE / 'spots.csv'}")
