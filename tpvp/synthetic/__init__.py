"""Generated plants and greenhouse rows for tests, calibration and offline experiments."""
