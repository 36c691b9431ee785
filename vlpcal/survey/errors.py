"""The survey layer's one error."""


class SurveyError(ValueError):
    """The survey cannot support what was asked (one line: which camera, what is missing)."""
