"""On-site work (the word "field" is kept for the systematic-error model: the field model).

The check before leaving the site (``check``) and where to stand next visit (``stations``).
"""
