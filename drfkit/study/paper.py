"""The paper's published numbers (Katyal, Wang, Hager, arXiv 2104.02799), as printed in
its figures and tables. These are the *targets* our results are compared with; nothing
in the book is computed from them. Values in the LaTeX source carry more digits than the
text; we keep those digits.
"""
from __future__ import annotations

# Fig. pendulum, middle: MAE on the (cos, sin) state, trained with max noise 0.5.
PENDULUM_MAE = {
    0.50: {"no_dynamics": 0.04651897668, "lstm": 0.03282828297, "drf": 0.004554806631},
    0.75: {"no_dynamics": 0.100267044, "lstm": 0.06742980505, "drf": 0.0426968253},
}

# Fig. pendulum, bottom: (MPIW, PICP %) for three dropout rates per model.
PENDULUM_PICP_MPIW = {
    "no_dynamics": [(1.63, 96.6), (2.48, 98.3), (3.34, 99.1)],
    "lstm": [(1.70, 94.5), (2.46, 98.4), (3.27, 99.2)],
    "drf": [(1.44, 97.5), (2.18, 98.7), (2.87, 99.2)],
}

# Fig. mae_chart_nuscenes: depth MAE (m) by salt-and-pepper probability.
PEDESTRIAN_MAE = {
    0.01: {"no_dynamics": 3.42, "lstm": 2.88, "monoloco": 2.56, "drf": 2.56},
    0.025: {"no_dynamics": 2.67, "lstm": 2.44, "monoloco": 2.32, "drf": 2.26},
    0.05: {"no_dynamics": 3.39, "lstm": 2.98, "monoloco": 2.87, "drf": 2.72},
}

# Fig. roc_curves: (MPIW m, PICP %) per noise level and model, dropout rate varied.
PEDESTRIAN_PICP_MPIW = {
    0.01: {
        "no_dynamics": [(32.3, 98.9), (21.2, 95.9), (15.5, 92), (11.8, 85.1)],
        "lstm": [(13.6, 92.7), (17.5, 95.3), (23.6, 98.6), (35.8, 99.3)],
        "monoloco": [(9.7, 87.1), (10.7, 88.8), (13, 92.3), (16.3, 94), (32, 96.8)],
        "drf": [(12.4, 91.3), (13.9, 93.6), (17.6, 96.8), (23.1, 98.6), (34.0, 99.4)],
    },
    0.025: {
        "no_dynamics": [(28.2, 97.8), (18.8, 96.3), (13.9, 92.9), (10.74, 87.6), (10.32, 80.8)],
        "lstm": [(30.9, 99.1), (20.75, 96.9), (15.7, 94.3), (12.5, 92.0), (10.57, 89.4)],
        "monoloco": [(14.1, 86.5), (17.1, 87.7), (23.7, 88.8), (40.6, 90.3)],
        "drf": [(30.2, 98.5), (21.1, 97.7), (16.3, 96), (13.3, 94.2)],
    },
    0.05: {
        "no_dynamics": [(8.6, 75.9), (10.14, 80.1), (12.9, 84.1), (17.3, 89.7), (25.8, 93.3)],
        "lstm": [(11.95, 86.8), (14.95, 89.7), (19.6, 92.7), (28.9, 95.8)],
        "monoloco": [(14.7, 81.6), (19, 83.6), (37.8, 85.8), (99.1, 91)],
        "drf": [(12.9, 89.7), (15.6, 93.3), (19.8, 95.4), (28.3, 96.9)],
    },
}

# Table performance: 25 forward passes after keypoint extraction, GTX 1080 (ms).
TIMING_MS = {"monoloco": 36.1, "drf": 12.3}
TIMING_SPEEDUP = 2.93

# Table pendulum_kalman_gain: (PICP %, MPIW, average time ms).
GATING = {
    "pendulum": {"no_dropout": (79.3, 0.04, 2.48), "random": (86.3, 0.30, 17.1),
                 "kalman_gain": (92.1, 0.24, 16.8), "always": (92.9, 0.48, 28.23)},
    "pedestrians": {"no_dropout": (86.0, 10.95, 1.63), "random": (87.4, 11.5, 4.25),
                    "kalman_gain": (87.7, 11.6, 4.06), "always": (89.7, 12.9, 11.3)},
}

# Text, pedestrian section: out-of-distribution MAE improvement of DRF over each baseline.
PEDESTRIAN_OOD_IMPROVEMENT = {"no_dynamics": 0.18, "lstm": 0.08, "monoloco": 0.04}
