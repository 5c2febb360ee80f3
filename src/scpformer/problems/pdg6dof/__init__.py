"""6-DoF free-final-time Mars powered descent (T-SCvx paper, Sec. III.B, Table 1)."""
