"""Rerun recordings of a calibration: the recording, its cell, its blueprint."""
