"""Helpers shared by the tests (not tests themselves); the fixtures are in ``tests/conftest.py``."""
