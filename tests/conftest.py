"""Shared fixtures. Helpers the tests import live in tests/helpers, never here: a test that
imports conftest.py runs it twice (tests/unit/test_test_layout.py checks)."""
