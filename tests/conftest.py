"""Fixtures for the test suite (helpers live in helpers.py)."""
import pytest

from helpers import compiled


@pytest.fixture(scope="session")
def cauer():
    """Paper 000's Cauer filter with the nonlinear resistor (index 2, one algebraic loop)."""
    return compiled("MCL.Examples.CauerFilter")
