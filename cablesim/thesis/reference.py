"""The thesis's real-robot numbers, printed beside the simulated ones (thesis tables 5.1,
6.3, 6.4, 6.5, 6.8 and 6.9; SPEC section 7).  Tables 6.4/6.5 stop at beta 0.3: the rows for
beta 0.2 and 0.1 have no thesis number."""

from __future__ import annotations

# (method, beta) -> (recall, precision, F_beta, IoU); mean over 42 test sequences, union
TABLE_6_4: dict[tuple[str, float], tuple[float, float, float, float]] = {
    ("segmentation", 1.0): (0.6791, 0.3642, 0.4205, 0.2868),
    ("ablation", 1.0): (0.6065, 0.4407, 0.4402, 0.3047),
    ("correlation", 1.0): (0.5911, 0.4758, 0.4971, 0.3488),
    ("segmentation", 0.5): (0.5842, 0.4153, 0.4100, 0.2912),
    ("ablation", 0.5): (0.5376, 0.4800, 0.4471, 0.2939),
    ("correlation", 0.5): (0.5123, 0.6117, 0.5660, 0.3771),
    ("segmentation", 0.4): (0.5842, 0.4153, 0.4102, 0.2912),
    ("ablation", 0.4): (0.5154, 0.4869, 0.4566, 0.2862),
    ("correlation", 0.4): (0.4618, 0.7488, 0.6533, 0.3914),
    ("segmentation", 0.3): (0.5842, 0.4153, 0.4115, 0.2912),
    ("ablation", 0.3): (0.5038, 0.4894, 0.4682, 0.2818),
    ("correlation", 0.3): (0.3430, 0.9001, 0.7505, 0.3281),
}

# intersection of the two actions
TABLE_6_5: dict[tuple[str, float], tuple[float, float, float, float]] = {
    ("segmentation", 1.0): (0.3512, 0.3921, 0.2727, 0.1714),
    ("ablation", 1.0): (0.2849, 0.4975, 0.2387, 0.1361),
    ("correlation", 1.0): (0.2343, 0.7171, 0.3259, 0.2068),
    ("segmentation", 0.5): (0.2435, 0.3658, 0.2341, 0.1274),
    ("ablation", 0.5): (0.2100, 0.4932, 0.2218, 0.0957),
    ("correlation", 0.5): (0.1860, 0.8193, 0.4310, 0.1766),
    ("segmentation", 0.4): (0.2435, 0.3658, 0.2468, 0.1274),
    ("ablation", 0.4): (0.1922, 0.4894, 0.2299, 0.0866),
    ("correlation", 0.4): (0.1599, 0.9449, 0.4711, 0.1576),
    ("segmentation", 0.3): (0.2435, 0.3658, 0.2644, 0.1274),
    ("ablation", 0.3): (0.1837, 0.4868, 0.2646, 0.0825),
    ("correlation", 0.3): (0.0501, 0.9956, 0.2916, 0.0501),
}

# beta -> (tau_v, c0_min, R2_min) tuned on the thesis's 8 validation sequences
TABLE_6_3: dict[float, tuple[float, float, float]] = {
    1.0: (0.31, 0.17, 0.66),
    0.5: (0.47, 0.20, 0.77),
    0.4: (0.47, 0.18, 0.86),
    0.3: (0.47, 0.36, 0.92),
}

# grade -> (count, % of 54 proposals)
TABLE_6_8: dict[str, tuple[int, int]] = {
    "correct_reachable": (20, 37),
    "correct_unreachable": (32, 59),
    "wrong_hose": (2, 4),
    "background": (0, 0),
}

# (grasps, action threshold) -> (recall, precision, F_0.4, IoU); ten cables
TABLE_6_9: dict[tuple[int, int], tuple[float, float, float, float]] = {
    (1, 1): (0.5570, 0.7882, 0.7317, 0.4756),
    (2, 1): (0.6658, 0.7111, 0.6934, 0.5179),
    (1, 2): (0.2404, 0.9092, 0.6252, 0.2378),
    (2, 2): (0.3987, 0.8838, 0.7218, 0.3812),
    (2, 3): (0.1072, 0.9193, 0.3673, 0.1065),
    (2, 4): (0.0329, 0.9797, 0.1507, 0.0329),
}

# method -> (recall, precision, IoU, EPE px, motion threshold px); MovingCables test set
TABLE_5_1: dict[str, tuple[float, float, float, float, float]] = {
    "MaskFlownet": (0.6098, 0.6415, 0.4079, 1.22, 2.5),
    "MfnProb": (0.8768, 0.7324, 0.6560, 0.65, 2.0),
    "Farneback": (0.8977, 0.3520, 0.3335, 1.56, 1.0),
    "GMFlow": (0.7202, 0.8077, 0.5925, 0.45, 1.0),
    "FlowFormer++": (0.7934, 0.8675, 0.6932, 0.44, 1.5),
    "MaskFlownet FT": (0.8286, 0.8295, 0.7022, 0.37, 2.5),
    "MfnProb FT": (0.8762, 0.8638, 0.7673, 0.32, 2.0),
}

METHOD_NAMES = {
    "segmentation": "Motion segmentation",
    "ablation": "No-gripper ablation",
    "correlation": "Motion correlation",
}
