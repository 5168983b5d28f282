"""hysteresis stage."""
