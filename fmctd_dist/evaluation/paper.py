"""The paper's cell beside ours in every report, from the tables each family's registry record carries."""

from fmctd_dist.registry import env_names, family_record


def paper_cell(method: str, env: str) -> str:
    """'100 ± 0 / 3.6 ± 0.6 s' for a method and an env name like 'pointmaze-medium', or '–'."""
    if env not in env_names():
        return "–"
    row = next((t.paper.get(method, {}).get(env) for t in family_record(env).tables if env in t.envs), None)
    if row is None:
        return "–"
    s, sd, t, td = row
    if sd is None or td is None:
        return f"{s:.0f} / {t:.1f} s"
    return f"{s:.0f} ± {sd:.0f} / {t:.1f} ± {td:.1f} s"
