"""Verification runs (ISO 9283), their uncertainty and decision, and the certificate."""
