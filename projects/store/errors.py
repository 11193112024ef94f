"""Errors of the campaign store (all derive from the project's SurveyError)."""
from common.errors import InputError, SurveyError


class CampaignError(SurveyError):
    """The campaign folder or database cannot be used as asked."""


class CampaignLockedError(CampaignError):
    """Another process is working on the campaign."""


class ScansArchivedError(CampaignError):
    """A command needs scans that were archived out of the campaign folder (``bridgesurvey archive --restore``)."""


class DuplicateImportError(InputError):
    """The same scan file (same checksum) is already in the campaign."""


__all__ = ["CampaignError", "CampaignLockedError", "DuplicateImportError", "InputError", "ScansArchivedError",
           "SurveyError"]
