"""Tests of the acps_worker package."""
