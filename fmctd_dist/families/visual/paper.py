"""The paper's visual PointMaze table (docs/reference.md §14): method -> (success % medium, large, planning time
s medium, large); it gives no standard deviations."""

MEANS = {"diffuser": (8, 0, 7.0, 6.7), "diffuser-replan": (8, 0, 26.4, 26.0),
         "diffusion-forcing": (66, 8, 14.5, 17.1), "mctd": (76, 2, 98.8, 320.1), "p-mctd": (86, 0, 6.8, 7.6),
         "s-mctd": (82, 31, 40.1, 168.7), "fast-mctd": (80, 32, 4.0, 5.1), "mctd-replan": (86, 31, 129.8, 419.7),
         "fast-mctd-replan": (84, 38, 14.3, 26.7)}
VISUAL: dict[str, dict[str, tuple[float, float | None, float, float | None]]] = {
    m: {"medium": (sm, None, tm, None), "large": (sl, None, tl, None)} for m, (sm, sl, tm, tl) in MEANS.items()}
