"""Names the files spell — fix statuses, detection reasons, lens models, fusion methods — as
enums whose members equal, print and format as their spelling, so rows, messages and callers
that compare strings are unchanged (what ``enum.StrEnum`` does from Python 3.11 on; vlpcal
runs on 3.10, as ROS 2 Humble's Ubuntu 22.04 ships it)."""

from enum import Enum


class Spelling(str, Enum):
    """A str-valued enum that is its value wherever a string is: ``str(m) == m == m.value``
    and ``f"{m}"`` is the value too."""

    __str__ = str.__str__
    __format__ = str.__format__
