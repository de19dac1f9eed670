"""The NanoBench star flight as a table, for the tests that inject faults into a copy of it."""

import gzip

import numpy as np
import pytest

from .test_flight_data import STAR


@pytest.fixture(scope="module")
def star_table():
    """`(header, table)` of `B8_star_fast_rep1.csv.gz` as the file holds it."""
    with gzip.open(STAR, "rt") as f:
        header = f.readline().strip().split(",")
    return header, np.loadtxt(STAR, delimiter=",", skiprows=1)
