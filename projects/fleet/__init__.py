"""Many bridges.

The status of each (``status``) and processing them on a Dask cluster (``process``).
"""
