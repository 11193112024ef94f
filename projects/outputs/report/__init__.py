"""Survey reports: a PDF for the bridge owner (one visit, a period, or the whole campaign).

``write_report`` is the entry point; :mod:`projects.outputs.report.content` gathers the
facts, :mod:`projects.outputs.report.plots` draws the figures and
:mod:`projects.outputs.report.pdf` lays out the document from the building blocks of
:mod:`projects.outputs.report.flowables`, with the analysis pages of
:mod:`projects.outputs.report.analysis_page` and the action log in words of
:mod:`projects.outputs.report.action_log`.
"""
from __future__ import annotations

import os
from pathlib import Path

from common.errors import InputError
from common.progress import ProgressCallback, report, scaled
from projects.outputs.report.content import ReportContent, ReportScope, gather
from projects.outputs.report.pdf import build_pdf
from projects.processing.stages import analyse_epoch_coarse, parameters
from projects.store.archive import away
from projects.store.campaign import Campaign
from projects.store.previews import decode_preview, encode_preview

__all__ = ["ReportContent", "ReportScope", "gather", "write_folder_report", "write_report"]


def _check_output(path: Path) -> None:
    if path.suffix.lower() != ".pdf":
        raise InputError(f"{path}: the report is a PDF; give an output name ending in .pdf")
    if not path.parent.is_dir():
        raise InputError(f"{path}: the folder {path.parent} does not exist; create it first")
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give a file name ending in .pdf")


def _preview_from_scan(c: Campaign):
    """For epochs planned before previews were stored: analyse the coarse scan again (slow, not saved).

    An epoch whose coarse scan is archived (:mod:`projects.store.archive`) has no map in the report.
    """
    def preview_of(label: str):
        coarse = c.files(label, "coarse")
        if not coarse or away(c, coarse):
            return None
        analysis = analyse_epoch_coarse(c, label, c.layout(c.epoch(label).datetime), parameters(c))
        return decode_preview(*encode_preview(analysis))
    return preview_of


def write_report(c: Campaign, path: str | os.PathLike, scope: ReportScope = ReportScope(), *,
                 author: str | None = None, progress: ProgressCallback | None = None, detail: bool = False) -> Path:
    """Write the PDF report of ``scope`` (default: whole campaign) to ``path``.

    Parameters
    ----------
    c : Campaign
        An open campaign (read-only is enough; nothing is changed).
    path : path-like
        Output file, ``.pdf``; written through a temporary file.
    scope : ReportScope, optional
        One epoch (a visit report, with the history up to it) or a period.
    author : str, optional, keyword-only
        Who prepared the report (default: the login name).
    progress : callable, optional, keyword-only
    detail : bool, keyword-only
        Add the appendix: every visit's page with flag codes, the field model's tables, the processing log.
        Default False: the main body (summary, the visits that need attention, histories, analysis, budget).
    """
    path = Path(path)
    _check_output(path)
    report(progress, 0.0, "reading the campaign")  # from the start: reading a long campaign takes seconds
    content = gather(c, scope, author=author, progress=scaled(progress, 0.0, 0.3))
    return build_pdf(content, path, preview_of=_preview_from_scan(c), progress=scaled(progress, 0.3, 1.0),
                     detail=detail)


def write_folder_report(folder: str | os.PathLike, path: str | os.PathLike, *, detail: bool = False,
                        progress: ProgressCallback | None = None) -> Path:
    """:func:`write_report` of the whole campaign in ``folder``, opened read-only for the time it takes.

    A function of paths only, so that it can run in a process of its own
    (:func:`common.processes.run_in_process`: the desktop application's *Write report*).
    """
    with Campaign.open(folder, writable=False) as c:
        return write_report(c, path, progress=progress, detail=detail)
