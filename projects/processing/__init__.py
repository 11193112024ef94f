"""Processing a campaign.

The parameters (``parameters``) and the two stages (``stages``): coarse scan to plan to centroids, then
displacements against the baseline, incrementally.
"""
