"""Tests of the macro PDE core."""
