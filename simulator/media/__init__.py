"""The media layer: video decode and encode (PyAV), the source's audio, and grid files with their lazily read sphere field.
"""
