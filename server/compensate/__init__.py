"""Compensation: joint commands from a calibrated model, and the files the service makes from a model."""
