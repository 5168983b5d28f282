"""What the online-compensator tests share (a helper module, not a test file)."""

from __future__ import annotations

#: A two-tendon GPI (``agpi``) of the robot's size: counts -> deg
AGPI_TRUTH = dict(
    theta0=0.4, a1_p=0.008, a3_p=0.0072, a4_p=-1.2, lam_p=0.06, sigma_p=0.25, r1_p=0.3,
    rn_p=3.5, a1_n=0.0065, a3_n=0.006, a4_n=-0.8, lam_n=0.06, sigma_n=0.2, r1_n=0.4, rn_n=3.0,
)  # fmt: skip
