"""Calibrate and diagnose between files and the solver: the workflow, the model's validation, identified parameters and position uncertainty."""
