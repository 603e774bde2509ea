"""checkpoints/README.md, generated from the manifests: what each shipped checkpoint dir is and who reads it.

Generated because a hand-written list went stale within sessions: every fact comes from a dir's own
``manifest.json`` or from the configs, so ``tests/test_checkpoint_index.py`` holds the committed file to
it. A dir is there because a config reads it (:func:`config_readers`) or :data:`PURPOSES` names what else
needs it; a dir that is neither is a snapshot and leaves the tree (git keeps its bytes). Regenerate with
``python jobs/report.py --checkpoints``.
"""

from __future__ import annotations

import json
from itertools import groupby
from pathlib import Path
from typing import Any

from fmctd_dist.config import REPO_ROOT, Config, group_names, is_ant, load_config, resolve_path
from fmctd_dist.errors import ConfigError, FmctdError
from fmctd_dist.family import HooksFor

CHECKPOINTS = REPO_ROOT / "checkpoints"
INDEX_FILE = "README.md"
EVAL = "eval"  # how a config reads a dir: its eval job's checks open it
EXPERT = "data.expert"  # ... or its dataset is made with it (AntMaze)

# Config words beyond each env x method default that name a shipped model: (env, words). The H=2 / H=10
# medium models of the jump ablation (run ablate-h); the visual maze's latent planners (the paper's frames: the
# notebook's latent lines; the visual envs' default plans [z, x, y] frames).
VARIANTS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("pointmaze-medium", ("jump=2",)),
    ("pointmaze-medium", ("jump=10",)),
    ("visual-pointmaze-medium", ("visual.plan_xy=false",)),
    ("visual-pointmaze-large", ("visual.plan_xy=false",)),
)

# Dirs no config reads by default that something else needs: dir -> who and why.
PURPOSES: dict[str, str] = {
    "visual-pointmaze-large-h5-s29": "jobs/gpu/gpu_train.py `VISUAL_START['large']`: the `visual-latent` set continues "
                                     "the large maze's boundary-loss latent lineage from it (val 0.0302 against the "
                                     "default `visual-pointmaze-large-h5`'s 0.0457; no shipped latent model descends "
                                     "from it); tests/test_gpu_train.py",
}

FAMILY_ORDER = ("pointmaze", "antmaze", "cube", "visual-pointmaze")
KIND_NAMES = {"df": "Diffusion Forcing planner", "diffuser": "Diffuser planner", "ant-goal-bc": "policy (ant)",
              "cube-goal-bc": "policy (cube arm)", "ant-direction-sac": "expert (ant, SAC; makes the AntMaze data)",
              "visual-vae": "VAE", "visual-estimator": "position estimator", "visual-invdyn": "inverse dynamics"}


def _configs() -> list[tuple[str, Config | None]]:
    """(its words, the config) for every env x method pair, and every variant with each Diffusion Forcing
    method; None where the words do not apply (``visual.plan_xy`` with the Diffuser is one ConfigError)."""
    out: list[tuple[str, Config | None]] = []
    for e in group_names("env"):
        for m in group_names("method"):
            out.append((f"env={e} method={m}", load_config([f"env={e}", f"method={m}"])))
    for e, words in VARIANTS:
        for m in group_names("method"):
            try:
                cfg: Config | None = load_config([f"env={e}", f"method={m}", *words])
            except ConfigError:
                cfg = None
            # the variants name Diffusion Forcing models; the Diffuser's one checkpoint would only be misread
            out.append((" ".join([f"env={e}", f"method={m}", *words]), cfg if cfg and cfg.model.kind == "df" else None))
    return out


def config_readers(hooks_for: HooksFor, absent: dict[str, str] | None = None) -> dict[str, list[str]]:
    """Checkpoint dir name -> the configs that read it (``env=E method=M [words]: how``, how = eval | data.expert);
    ``hooks_for``: env name -> its family's hook module (``fmctd_dist.families.hooks_for``).

    A config whose eval checks fail because its planner checkpoint is not there goes to ``absent`` (dir name ->
    the config), when given; any other failure of those checks is raised: a shipped config must pass them."""
    from fmctd_dist.evaluation.job_upload import checkpoints_read  # deferred: the eval job's imports (torch)

    readers: dict[str, list[str]] = {}
    for words, cfg in _configs():
        if cfg is None:
            continue
        try:
            names = [p.removeprefix("checkpoints/") for p in checkpoints_read(cfg, hooks_for)]
        except FmctdError:
            if cfg.checkpoint_dir().exists():
                raise
            if absent is not None:
                absent.setdefault(cfg.checkpoint_dir().name, words)
            names = []
        for name in names:
            readers.setdefault(name, []).append(f"{words}: {EVAL}")
        expert = resolve_path(cfg.data.expert).resolve()
        if is_ant(cfg.env.name) and expert.parent == CHECKPOINTS.resolve():
            readers.setdefault(expert.name, []).append(f"{words}: {EXPERT}")
    return readers


def _reader_cell(name: str, readers: dict[str, list[str]]) -> str:
    """The shortest honest summary of who reads ``name``: how (eval / data.expert), one config and how many more;
    or its purpose."""
    if name in readers:
        lines = readers[name]
        how = " and ".join(sorted({line.rsplit(": ", 1)[1] for line in lines}))
        # the paper's method names it when it can (the readers are listed by method, alphabetically)
        first = next((line for line in lines if "method=fast-mctd:" in line), lines[0]).rsplit(": ", 1)[0]
        more = f" and {len(lines) - 1} more" if len(lines) > 1 else ""
        return f"{how}: `{first}`{more}"
    return PURPOSES.get(name, "**nothing** (a snapshot: remove it, see docs/notebook/checkpoint-snapshots.md)")


def _family(m: dict[str, Any]) -> str:
    """The env family it belongs to, by the env names' convention ``<family>-<size>`` (pointmaze-medium,
    cube-triple, visual-pointmaze-large); the ant expert (trained in an open arena) with the AntMaze it makes
    data for."""
    if m.get("kind") == "ant-direction-sac":
        return "antmaze"
    return _env(m).rsplit("-", 1)[0]


def _env(m: dict[str, Any]) -> str:
    cfg = m.get("config") if isinstance(m.get("config"), dict) else {}
    env = m.get("env") or (cfg.get("env") or {}).get("name")
    return str(env) if env else "open arena" if m.get("kind") == "ant-direction-sac" else "?"


def _steps(m: dict[str, Any]) -> int | None:
    for key in ("train_steps", "steps", "updates"):
        if isinstance(m.get(key), int):
            return int(m[key])
    return None


def _num(x: Any, fmt: str = ",") -> str:
    return "—" if x is None else format(x, fmt)


def _hours(seconds: Any) -> str:
    return "—" if seconds is None else f"{float(seconds) / 3600:.2f}"


def what_it_is(m: dict[str, Any]) -> str:
    """Model kind, env, and for planners the jump H, tokens (context + plan) and frame layout."""
    kind = str(m.get("model_kind") or m.get("kind") or "?")
    text = f"{KIND_NAMES.get(kind, kind)}, {_env(m)}"
    if kind in ("df", "diffuser"):
        cfg = m.get("config") or {}
        xy = ", [z, x, y] frames" if (cfg.get("visual") or {}).get("plan_xy") else ""
        text += f", H={cfg.get('jump', '?')}, {m.get('n_tokens', '?')} tokens{xy}"
    return text


def quality(m: dict[str, Any]) -> str:
    """The quality numbers the manifest records (validation losses and the checks its trainer ran)."""
    kind = str(m.get("model_kind") or m.get("kind") or "")
    met = m.get("metrics") or {}
    parts = []
    val = (m.get("final_losses") or {}).get("val")
    if val is not None:
        parts.append(f"val loss {val:.4g}")
    if kind.endswith("goal-bc"):
        if met.get("val_loss") is not None:
            parts.append(f"val loss {met['val_loss']:.4g}")
        reach = (met.get("reach") or {}).get("policy") or {}
        if "reach_rate" in reach:
            parts.append(f"subgoal reach {reach['reach_rate']:.0%} ({reach.get('tries')} tries)")
    elif kind == "ant-direction-sac":
        ev = met.get("eval") or {}
        parts.append(f"eval success {ev.get('success', 0):.0%}, speed {ev.get('speed_mean', 0):.2f}, "
                     f"falls {ev.get('fall_rate', 0):.0%} ({ev.get('episodes')} episodes)")
    elif kind == "visual-vae":
        parts.append(f"val PSNR {met.get('val_psnr_db', 0):.1f} dB, linear (x, y) RMSE "
                     f"{met.get('val_linear_xy_rmse', 0):.2f}")
    elif kind == "visual-estimator":
        parts.append(f"val RMSE {met.get('val_rmse', 0):.3f} (sampled z {met.get('val_sampled_rmse', 0):.3f})")
    elif kind == "visual-invdyn":
        reach = (met.get("reach") or {}).get("invdyn") or {}
        parts.append(f"val MSE {met.get('val_mse', 0):.4f}, segment reach {reach.get('reach_rate', 0):.0%}")
    return "; ".join(parts) or "—"


def lineage(m: dict[str, Any]) -> str:
    """The ``init_from`` parent (path @ digest, its steps) and the lineage totals the manifest records."""
    parent = m.get("init_from") or {}
    if not parent:
        return "from scratch"
    path = str(parent.get("path", "?")).removeprefix("checkpoints/")
    text = f"`{path}` @ `{str(parent.get('digest', '?'))[:8]}` ({_num(parent.get('train_steps'))} steps"
    if parent.get("lineage_cpu_s") is not None:
        text += f", lineage {_hours(parent['lineage_cpu_s'])} CPU h"
    return text + ")"


def size_mb(d: Path) -> float:
    return sum(p.stat().st_size for p in d.rglob("*") if p.is_file()) / 1e6


def rows(root: Path, readers: dict[str, list[str]]) -> list[dict[str, Any]]:
    """One dict per dir under ``root``, sorted by family then name; a dir without a manifest is an error."""
    out = []
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        path = d / "manifest.json"
        if not path.is_file():
            raise ConfigError(f"{d} has no manifest.json: every checkpoint dir ships its manifest; remove the dir "
                              "or write it with the job that trained it")
        m = json.loads(path.read_text())
        out.append({"family": _family(m), "name": d.name, "what": what_it_is(m), "digest": str(m.get("digest", "?")),
                    "params": m.get("param_count"), "steps": _steps(m), "lineage_steps": m.get("lineage_steps"),
                    "cpu_h": _hours(m.get("cpu_time_s")), "wall_h": _hours(m.get("wall_time_s")),
                    "lineage_cpu_h": _hours(m.get("lineage_cpu_s")), "parent": lineage(m),
                    "quality": quality(m), "mb": size_mb(d), "read_by": _reader_cell(d.name, readers)})
    order = {f: i for i, f in enumerate(FAMILY_ORDER)}
    return sorted(out, key=lambda r: (order.get(r["family"], len(order)), r["name"]))


def render(table: list[dict[str, Any]], absent: dict[str, str] | None = None) -> str:
    """The markdown of checkpoints/README.md for ``table`` (from :func:`rows`); ``absent``: dirs a config names
    that are not there (name -> a config that names it)."""
    total = sum(r["mb"] for r in table)
    lines = [
        "# checkpoints/",
        "",
        "<!-- generated by `python jobs/report.py --checkpoints` (fmctd_dist/checkpoint_index.py) from each dir's "
        "manifest.json; tests/test_checkpoint_index.py keeps it equal to the manifests: do not edit by hand -->",
        "",
        f"{len(table)} dirs, {total:.1f} MB. Each holds `model.pt` and `manifest.json`; every dir is read by a "
        "config (*eval*: the eval job's checks open it, so `ray job submit` uploads it; *data.expert*: the "
        "AntMaze data is made with it), or by the purpose named in its last column. Snapshots that nothing "
        "reads left the tree: docs/notebook/checkpoint-snapshots.md lists their digests and the commits that "
        "hold their bytes.",
        "",
        "Columns: *steps* is this run's optimiser steps (SAC updates for the expert), *lineage* the steps of the "
        "whole `init_from` chain as the manifest records them; *CPU h* / *wall h* are this run's own, *lineage "
        "CPU h* the chain's (— where not recorded, e.g. GPU runs); *started from* is the `init_from` parent at "
        "training time (its path may hold newer weights since; the digest names the weights).",
        "",
    ]
    head = ("| dir | what | digest | params | steps | lineage | CPU h | wall h | lineage CPU h | started from | "
            "quality (manifest) | MB | read by |")
    for fam, group in groupby(table, key=lambda r: r["family"]):
        lines += [f"## {fam}", "", head, "|" + "---|" * 13]
        lines += [f"| `{r['name']}` | {r['what']} | `{r['digest']}` | {_num(r['params'])} | {_num(r['steps'])} | "
                  f"{_num(r['lineage_steps'])} | {r['cpu_h']} | {r['wall_h']} | {r['lineage_cpu_h']} | "
                  f"{r['parent']} | {r['quality']} | {r['mb']:.1f} | {r['read_by']} |" for r in group]
        lines.append("")
    if absent:
        lines += ["## Named by a config, not shipped", "",
                  "A run with such a config stops with a missing-checkpoint error naming the command that trains it.",
                  ""]
        lines += [f"- `{name}`: {absent[name]}" for name in sorted(absent)]
        lines.append("")
    return "\n".join(lines)


def checkpoint_index(root: Path, readers: dict[str, list[str]], absent: dict[str, str]) -> str:
    """checkpoints/README.md's text for the dirs under ``root`` today; ``readers`` and ``absent`` as
    :func:`config_readers` fills them."""
    return render(rows(root, readers), {name: f"`{words}`" for name, words in absent.items()})


def write_index(hooks_for: HooksFor, root: Path = CHECKPOINTS) -> Path:
    """Write ``root``/README.md (~150 configs' checks, half a minute); returns its path."""
    absent: dict[str, str] = {}
    readers = config_readers(hooks_for, absent)
    path = root / INDEX_FILE
    path.write_text(checkpoint_index(root, readers, absent))
    return path
