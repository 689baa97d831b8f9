"""tpvp: one-shot view planning guided by the previous-session reconstruction."""

__version__ = "0.1.0"
