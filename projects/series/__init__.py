"""What a campaign imports beside its scans.

Camera series (``camera``), environment series (``environment``), design predictions (``predictions``) and the
events and series every time plot shows (``context``).
"""
