"""The ``vlpcal`` command, a module per user around what they share. Thin: parses options and
calls the layers below.

- :mod:`.common`: the group, the one-line user error, output files checked before any work;
- :mod:`.plan`: the installer (``plan``, ``check``);
- :mod:`.survey`: the surveyor (``survey plan | capture | calibrate``);
- :mod:`.locate`: the integrator (``locate``);
- :mod:`.track`: a moving LED from unsynchronised cameras (``track``);
- :mod:`.interchange`: other tools' camera files (``export``, ``import``);
- :mod:`.demo`: the demo and the simulator (``demo``, ``simulate``);
- :mod:`.show`: what a deployment holds (``show``).

Heavy modules (cv2, scipy, matplotlib) are imported inside commands, so ``vlpcal --help``
starts fast.

Each command's module is imported when that command runs (:data:`.common.COMMANDS`).
"""

from .common import UserError, main

__all__ = ["UserError", "main"]
