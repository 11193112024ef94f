"""Errors of the registration layer (all under the product's one root, ``SurveyError``)."""
from common.errors import InputError, ProcessingError, SurveyError


class RegistrationError(ProcessingError):
    """Two epochs could not be registered (too few tie points, ICP diverged, ...)."""


__all__ = ["InputError", "ProcessingError", "RegistrationError", "SurveyError"]
