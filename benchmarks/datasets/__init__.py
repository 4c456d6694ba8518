"""Readers for the datasets in ``../shared/data`` (one module per dataset; see :mod:`benchmarks.datasets.base`)."""
