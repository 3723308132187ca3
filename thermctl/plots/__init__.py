"""Matplotlib figures, one module per topic (used by the report)."""
