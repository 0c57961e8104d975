"""Embedded scenario configurations (installed as ``fuzzyslam.configs``)."""
