"""The daemon tests' fixtures (params, the replayed table) for the page tests."""

from tests.daemon.conftest import e2e_table, params  # noqa: F401
