"""Physical constants, defined once (SI units)."""

SPEED_OF_LIGHT = 299_792_458.0
"""The speed of light in vacuum [m/s] (exact, SI)."""
