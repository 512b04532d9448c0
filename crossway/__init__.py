"""crossway: multi-agent deep RL for unsignalled intersections (after Capasso et al.)."""

__version__ = "0.1.0"
