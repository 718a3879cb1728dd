"""Head traces: the head-path type and its interpolation, scripted paths, and one reader module per dataset family (``readers/``).
"""
