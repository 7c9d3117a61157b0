"""Tests of the laser tracker driver."""
