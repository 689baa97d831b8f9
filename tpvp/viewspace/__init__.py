"""Candidate views: view spaces as objects (positions, look-ats, table, initial views, range)."""
