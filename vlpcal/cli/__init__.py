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

Imports inside the commands' functions are deliberate, for start time: each command's module is
imported when that command runs (:data:`.common.COMMANDS`), and a command imports vlpcal's
layers and heavy packages (cv2, scipy, matplotlib) in its body, so ``vlpcal --help`` and every
command start without paying for the others' imports.
"""

from .common import UserError, main

__all__ = ["UserError", "main"]
