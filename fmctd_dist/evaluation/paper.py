"""The paper's PointMaze, AntMaze, robot-arm cube and visual PointMaze numbers, printed beside ours in every report.

(success %, success std, planning time s, time std) per (method, maze). Planning times are
the authors' GPU times; compare ratios, not seconds, with our CPU runs.
"""

PAPER_POINTMAZE: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "diffuser": {"medium": (58, 6, 6.6, 0.1), "large": (44, 8, 6.5, 0.1), "giant": (0, 0, 6.4, 0.1)},
    "diffuser-replan": {"medium": (60, 0, 40.6, 2.7), "large": (40, 0, 55.1, 1.8), "giant": (0, 0, 137.8, 0.4)},
    "diffusion-forcing": {"medium": (65, 16, 9.8, 1.0), "large": (74, 9, 12.5, 0.5), "giant": (50, 10, 45.6, 3.2)},
    "mctd": {"medium": (100, 0, 59.2, 27.1), "large": (98, 6, 174.6, 27.2), "giant": (100, 0, 264.2, 33.8)},
    "p-mctd": {"medium": (96, 8, 7.4, 1.1), "large": (100, 0, 7.0, 0.6), "giant": (100, 0, 9.8, 1.3)},
    "s-mctd": {"medium": (100, 0, 9.7, 1.2), "large": (84, 8, 226.1, 114.4), "giant": (100, 0, 18.9, 2.8)},
    "fast-mctd": {"medium": (100, 0, 3.6, 0.6), "large": (80, 0, 4.1, 0.4), "giant": (100, 0, 2.4, 0.1)},
}

PAPER_ANTMAZE: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "diffuser": {"medium": (36, 15, 6.2, 0.1), "large": (14, 16, 6.5, 0.1), "giant": (0, 0, 6.5, 0.1)},
    "diffuser-replan": {"medium": (40, 18, 60.3, 4.2), "large": (26, 13, 73.7, 1.9), "giant": (0, 0, 193.0, 0.4)},
    "diffusion-forcing": {"medium": (90, 10, 14.0, 3.8), "large": (57, 6, 24.1, 1.8), "giant": (24, 12, 67.0, 3.4)},
    "mctd": {"medium": (100, 0, 68.0, 3.8), "large": (98, 6, 132.1, 12.7), "giant": (94, 9, 214.5, 11.0)},
    "p-mctd": {"medium": (96, 8, 2.8, 0.2), "large": (90, 10, 3.1, 0.1), "giant": (89, 16, 4.2, 0.1)},
    "s-mctd": {"medium": (94, 1, 12.5, 0.7), "large": (68, 13, 40.1, 2.6), "giant": (82, 14, 40.3, 2.9)},
    "fast-mctd": {"medium": (98, 6, 2.2, 0.1), "large": (77, 14, 2.2, 0.1), "giant": (90, 16, 2.5, 0.1)},
}
# Robot table (the paper's tab:robot_result, its \graypm stds; docs/reference.md §13 lists the means only).
PAPER_CUBE: dict[str, dict[str, tuple[float, float | None, float, float | None]]] = {
    "diffuser": {"single": (78, 23, 6.3, 0.1), "double": (12, 10, 6.4, 0.1), "triple": (8, 10, 6.5, 0.1)},
    "diffuser-replan": {"single": (92, 13, 21.4, 2.4), "double": (12, 13, 71.2, 5.1), "triple": (4, 8, 130.9, 11.6)},
    "diffusion-forcing": {"single": (100, 0, 2.9, 0.2), "double": (18, 11, 15.2, 2.2), "triple": (16, 8, 15.9, 1.2)},
    "mctd-replan": {"single": (100, 0, 9.2, 0.9), "double": (78, 11, 38.8, 4.7), "triple": (40, 21, 102.0, 6.9)},
    "p-mctd-replan": {"single": (100, 0, 2.9, 0.2), "double": (80, 9, 6.5, 2.3), "triple": (50, 21, 11.4, 2.8)},
    "s-mctd-replan": {"single": (100, 0, 8.5, 0.5), "double": (75, 3, 35.7, 18.2), "triple": (42, 11, 58.7, 33.0)},
    "fast-mctd-replan": {"single": (100, 0, 3.0, 0.2), "double": (77, 11, 5.9, 1.7), "triple": (50, 16, 9.1, 1.8)},
}
# Visual PointMaze table (docs/reference.md §14): success %, planning time s; no standard deviations given.
_VISUAL = {"diffuser": (8, 0, 7.0, 6.7), "diffuser-replan": (8, 0, 26.4, 26.0),
           "diffusion-forcing": (66, 8, 14.5, 17.1),
           "mctd": (76, 2, 98.8, 320.1), "p-mctd": (86, 0, 6.8, 7.6), "s-mctd": (82, 31, 40.1, 168.7),
           "fast-mctd": (80, 32, 4.0, 5.1), "mctd-replan": (86, 31, 129.8, 419.7),
           "fast-mctd-replan": (84, 38, 14.3, 26.7)}
PAPER_VISUAL: dict[str, dict[str, tuple[float, float | None, float, float | None]]] = {
    m: {"medium": (sm, None, tm, None), "large": (sl, None, tl, None)} for m, (sm, sl, tm, tl) in _VISUAL.items()}
PAPER = {"pointmaze": PAPER_POINTMAZE, "antmaze": PAPER_ANTMAZE, "cube": PAPER_CUBE, "visual-pointmaze": PAPER_VISUAL}


def paper_cell(method: str, env: str) -> str:
    """'100 ± 0 / 3.6 ± 0.6 s' for a method and an env name like 'pointmaze-medium', or '–'."""
    robot, _, maze = env.rpartition("-")
    row = PAPER.get(robot, {}).get(method, {}).get(maze)
    if row is None:
        return "–"
    s, sd, t, td = row
    if sd is None or td is None:
        return f"{s:.0f} / {t:.1f} s"
    return f"{s:.0f} ± {sd:.0f} / {t:.1f} ± {td:.1f} s"
