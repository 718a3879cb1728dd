"""The sphere layer: pure-numpy geometry of the sphere, equirect and perspective views, the paper's window grid, headset frusta and lon/lat cells.

Conventions (once, here and in :mod:`simulator.sphere.geometry`): angles in degrees at every
boundary, radians inside; world frame +x right, +y up, +z forward (lon = 0, lat = 0).
"""
