"""The paper's PointMaze and AntMaze tables (its Table "Maze results"): method -> maze -> (success %, std,
planning time s, std). Planning times are the authors' GPU times; compare ratios, not seconds, with CPU runs."""

POINTMAZE: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "diffuser": {"medium": (58, 6, 6.6, 0.1), "large": (44, 8, 6.5, 0.1), "giant": (0, 0, 6.4, 0.1)},
    "diffuser-replan": {"medium": (60, 0, 40.6, 2.7), "large": (40, 0, 55.1, 1.8), "giant": (0, 0, 137.8, 0.4)},
    "diffusion-forcing": {"medium": (65, 16, 9.8, 1.0), "large": (74, 9, 12.5, 0.5), "giant": (50, 10, 45.6, 3.2)},
    "mctd": {"medium": (100, 0, 59.2, 27.1), "large": (98, 6, 174.6, 27.2), "giant": (100, 0, 264.2, 33.8)},
    "p-mctd": {"medium": (96, 8, 7.4, 1.1), "large": (100, 0, 7.0, 0.6), "giant": (100, 0, 9.8, 1.3)},
    "s-mctd": {"medium": (100, 0, 9.7, 1.2), "large": (84, 8, 226.1, 114.4), "giant": (100, 0, 18.9, 2.8)},
    "fast-mctd": {"medium": (100, 0, 3.6, 0.6), "large": (80, 0, 4.1, 0.4), "giant": (100, 0, 2.4, 0.1)},
}

ANTMAZE: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "diffuser": {"medium": (36, 15, 6.2, 0.1), "large": (14, 16, 6.5, 0.1), "giant": (0, 0, 6.5, 0.1)},
    "diffuser-replan": {"medium": (40, 18, 60.3, 4.2), "large": (26, 13, 73.7, 1.9), "giant": (0, 0, 193.0, 0.4)},
    "diffusion-forcing": {"medium": (90, 10, 14.0, 3.8), "large": (57, 6, 24.1, 1.8), "giant": (24, 12, 67.0, 3.4)},
    "mctd": {"medium": (100, 0, 68.0, 3.8), "large": (98, 6, 132.1, 12.7), "giant": (94, 9, 214.5, 11.0)},
    "p-mctd": {"medium": (96, 8, 2.8, 0.2), "large": (90, 10, 3.1, 0.1), "giant": (89, 16, 4.2, 0.1)},
    "s-mctd": {"medium": (94, 1, 12.5, 0.7), "large": (68, 13, 40.1, 2.6), "giant": (82, 14, 40.3, 2.9)},
    "fast-mctd": {"medium": (98, 6, 2.2, 0.1), "large": (77, 14, 2.2, 0.1), "giant": (90, 16, 2.5, 0.1)},
}
