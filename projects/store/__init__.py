"""The campaign store: one SQLite database and the folder of imported files, handed out as typed records.

``campaign`` (the :class:`~projects.store.campaign.Campaign` that owns the connection, the lock and the
transactions, and the core tables), ``repositories`` (the rest, hanging off the campaign: camera and
environment series, events, predictions, cross-validations, comparisons), ``schema``
(the tables and their migrations), ``records`` (the frozen records it hands out), ``history`` (one
displacement history per target), ``limits`` (warning and alarm rules), ``previews`` (the stored
reflectance-map previews) and ``errors``.
"""
