"""Numbers published in seed 000 (§3), converted to SI (the paper works in cm).

These are data, not code: the tests and the demo reproduce what they allow.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SEED_A_POINTS_W", "SEED_A_POINTS_0", "SEED_A_R_INIT", "SEED_A_R_OPT", "SEED_A_T", "SEED_B_R",
           "SEED_B_T", "SEED_H", "TABLE2_DESIRED", "TABLE2_MEASURED_A", "TABLE2_MEASURED_B"]

_CM = 1e-2

#: Projector A's three correspondences ^W P_i <-> ^0 P_i (seed §3), metres.
SEED_A_POINTS_W = np.array([[0.0, 0.0, 0.0], [60.0, 60.0, 0.0], [0.0, 90.0, 0.0]]) * _CM
SEED_A_POINTS_0 = np.array([[240.0, -90.0, -290.0], [297.09, -28.15, -290.0], [236.50, -10.40, -290.0]]) * _CM

#: Ceiling height implied by the published ^0 P (z_0 = -H), metres.
SEED_H = 2.90

#: Published initial R (eq. 23) and optimised R (eq. 29) of projector A, 4 decimals as printed.
SEED_A_R_INIT = np.array([[0.9992, -0.0399, 0.0], [0.0399, 0.9992, 0.0], [0.0, 0.0, 1.0]])
SEED_A_R_OPT = np.array([[0.9991, -0.0419, 0.0], [0.0419, 0.9991, 0.0], [0.0, 0.0, 1.0]])
SEED_A_T = np.array([240.0, -90.0, -290.0]) * _CM

#: Projector B's published result (its correspondences are not given).
SEED_B_R = np.array([[0.9996, 0.0284, 0.0], [-0.0284, 0.9996, 0.0], [0.0, 0.0, 1.0]])
SEED_B_T = np.array([273.0, 455.0, -290.0]) * _CM

#: Table 2: desired world points and where the spots of A and B landed (metres).
TABLE2_DESIRED = np.array([[-200, -200], [-200, 0], [-200, 200], [0, -200], [0, 0], [0, 200],
                           [200, -200], [200, 0], [200, 200]], dtype=float) * _CM
TABLE2_MEASURED_A = np.array([[-199.7, -201.6], [-199.4, -0.2], [-200.2, 200.5], [-0.5, -198.5], [2.2, -1.9],
                              [2.5, 200.1], [201.4, -200.5], [204.3, 0.9], [203.5, 202.3]]) * _CM
TABLE2_MEASURED_B = np.array([[-200.7, -199.7], [-198.4, -4.9], [-198.7, 203.6], [2.3, -198.3], [-1.6, -0.1],
                              [-2.8, 197.2], [200.6, -198.3], [198.5, -0.5], [199.3, 194.9]]) * _CM
