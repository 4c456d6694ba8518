"""Accuracy benchmark on real walks (desktop only; never imported by ``core``)."""
