"""Tests of the PLC attachment."""
