"""The core layer: the package exception, fixed choice lists, progress callbacks, output files, resource checks and the map cache.

Nothing here imports another layer of the package.
"""
