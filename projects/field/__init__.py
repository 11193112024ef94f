"""Field work.

The check before leaving the site (``check``) and where to stand next visit (``stations``).
"""
