"""Execution path: local paths around the plant and the shortest open path through the views."""
