"""Synthetic fixtures shared by the tests (analytic scenes, geometry helpers)."""
