"""dfcoa_opt: multi-robot formation control with obstacle avoidance.

The DFCOA reference implementation (paper 000), companion-paper controllers
(package ``comparisons``), a simulator with LiDAR and a benchmark harness.
"""

__version__ = "0.1.0"
