"""The paper's robot table (tab:robot_result, with its graypm stds): method -> cube type -> (success %, std,
planning time s, std); the authors' GPU times."""

CUBE: dict[str, dict[str, tuple[float, float | None, float, float | None]]] = {
    "diffuser": {"single": (78, 23, 6.3, 0.1), "double": (12, 10, 6.4, 0.1), "triple": (8, 10, 6.5, 0.1)},
    "diffuser-replan": {"single": (92, 13, 21.4, 2.4), "double": (12, 13, 71.2, 5.1), "triple": (4, 8, 130.9, 11.6)},
    "diffusion-forcing": {"single": (100, 0, 2.9, 0.2), "double": (18, 11, 15.2, 2.2), "triple": (16, 8, 15.9, 1.2)},
    "mctd-replan": {"single": (100, 0, 9.2, 0.9), "double": (78, 11, 38.8, 4.7), "triple": (40, 21, 102.0, 6.9)},
    "p-mctd-replan": {"single": (100, 0, 2.9, 0.2), "double": (80, 9, 6.5, 2.3), "triple": (50, 21, 11.4, 2.8)},
    "s-mctd-replan": {"single": (100, 0, 8.5, 0.5), "double": (75, 3, 35.7, 18.2), "triple": (42, 11, 58.7, 33.0)},
    "fast-mctd-replan": {"single": (100, 0, 3.0, 0.2), "double": (77, 11, 5.9, 1.7), "triple": (50, 16, 9.1, 1.8)},
}
