"""Pytest root configuration: tests import the package from this checkout."""
