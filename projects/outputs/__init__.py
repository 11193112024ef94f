"""Everything written for a reader.

Exports (``exports``), figures (``figures``), the PDF report (``report``), the field sheet (``field_sheet``),
the fleet report (``fleet_report``) and what the application shows of one epoch (``inspection``).
"""
