"""The surveyor's commands (``vlpcal survey plan | capture | calibrate``): the group, and a
module per command (what they share: :mod:`.survey_shared`):

- :mod:`.survey_plan`: where to put the LED (``survey plan``);
- :mod:`.survey_capture`: the session with live cameras (``survey capture``);
- :mod:`.survey_calibrate`: the cameras from a survey bundle (``survey calibrate``).
"""

from __future__ import annotations

from .common import main
from .survey_calibrate import survey_calibrate
from .survey_capture import survey_capture
from .survey_plan import survey_plan


@main.group()
def survey():
    """Survey calibration: cameras (and region maps) from LED measurements at known points.

    Example: vlpcal survey plan -d planned.yaml --out survey-plan.csv
    """


for command in (survey_plan, survey_capture, survey_calibrate):
    survey.add_command(command)
